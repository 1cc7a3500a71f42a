//! Worker tags: a job that requires tags goes only to workers that have them all, and says
//! it is stuck while no live worker does.

use super::*;

/// A worker of 4 threads named `name` with `tags`.
fn tagged_worker(c: &mut Connection, name: &str, tags: &[String], now: i64) -> u64 {
    let mut joining = joining(name, None);
    joining.profile.tags = tags;
    join(c, &joining, now, TIMING.live_since(now)).unwrap().id
}

#[test]
fn a_job_that_requires_tags_goes_only_to_workers_that_have_them_all() {
    let mut c = db();
    let mut spec = JobSpec::new(scene().digest);
    (spec.width, spec.height, spec.tile_size, spec.spp) = (16, 16, Some(16), 1);
    spec.require_tags = vec!["gpu".into(), "studio-a".into()];
    let plan = crate::spec::plan(spec, &scene(), 1_000).unwrap();
    let j = submit(&mut c, &plan, 0).unwrap();
    let plain = worker(&mut c, "plain", 0);
    let half = tagged_worker(&mut c, "half", &["gpu".into()], 0);
    assert_eq!(lease(&mut c, plain, 1, TIMING).unwrap(), None);
    assert_eq!(lease(&mut c, half, 1, TIMING).unwrap(), None);
    let stuck = job_status(&c, j, 1, TIMING.live_since(1)).unwrap().stuck;
    let stuck = stuck.expect("no live worker has both tags");
    assert!(
        stuck.contains("2 without the tags it requires (gpu, studio-a)")
            && stuck.contains("`--tags gpu,studio-a`"),
        "{stuck}"
    );
    let tags = ["studio-a".to_string(), "fast".into(), "gpu".into()];
    let full = tagged_worker(&mut c, "full", &tags, 2);
    assert_eq!(
        job_status(&c, j, 2, TIMING.live_since(2)).unwrap().stuck,
        None
    );
    assert_eq!(lease(&mut c, full, 3, TIMING).unwrap().unwrap().job_id, j);
    let listed = workers::list(&c, 3, TIMING.live_since(3), 0)
        .unwrap()
        .workers;
    assert_eq!(listed.iter().find(|w| w.id == full).unwrap().tags, tags);
    // A job that requires nothing goes to any worker.
    let any = job(&mut c, 1, 0, 3, 4);
    assert_eq!(
        lease(&mut c, plain, 5, TIMING).unwrap().unwrap().job_id,
        any
    );
}

#[test]
fn tags_are_words_and_a_bounded_number() {
    let check = |tags: &[&str]| {
        let tags: Vec<String> = tags.iter().map(|t| t.to_string()).collect();
        crate::spec::check_tags("tags", &tags).map_err(|e| (e.field, e.message))
    };
    assert!(check(&["gpu", "studio-a", "v1.2", "big_ram"]).is_ok());
    for bad in ["", "a b", "ü", "gpu,fast", &"x".repeat(65)] {
        let (field, message) = check(&[bad]).unwrap_err();
        assert_eq!(field, "tags");
        assert!(
            message.contains("a tag is 1 to 64 ASCII letters"),
            "{message}"
        );
    }
    let many: Vec<String> = (0..33).map(|i| format!("t{i}")).collect();
    let refs: Vec<&str> = many.iter().map(String::as_str).collect();
    assert!(check(&refs).unwrap_err().1.starts_with("at most 32 tags"));
}
