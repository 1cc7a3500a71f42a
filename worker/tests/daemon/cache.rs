//! The scene cache: a scene is downloaded once per machine, a corrupted cache file is
//! replaced by a fresh download, and the folder keeps to its size limit.

use crate::common::*;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn scenes_are_downloaded_once_and_a_corrupt_copy_is_replaced() {
    let Setup {
        dir,
        s,
        c,
        glb,
        scene,
    } = setup().await;
    let cache = dir.path().join("cache");
    let file = cache.join(format!("{}.glb", scene.digest));

    // Two frames, four tiles each: eight tasks, one download.
    let one = spec(&scene.digest, 2, 1, 1);
    let job1 = create_job(&s, &c, &one).await;
    let w = TestWorker::start(&s.base, &cache, None);
    wait_until_done(&s, &c, job1.id).await;
    let summary = w.shutdown().await.unwrap();
    assert_eq!((summary.tasks_done, summary.scenes_downloaded), (8, 1));
    assert_eq!(std::fs::read(&file).unwrap(), glb);
    let (glbs, other) = cache_entries(&cache);
    assert_eq!((glbs.len(), other.len()), (1, 0), "{glbs:?} {other:?}");

    // A new worker process on the same machine reads the cached file.
    let job2 = create_job(&s, &c, &one).await;
    let w = TestWorker::start(&s.base, &cache, None);
    wait_until_done(&s, &c, job2.id).await;
    let summary = w.shutdown().await.unwrap();
    assert_eq!((summary.tasks_done, summary.scenes_downloaded), (8, 0));

    // A damaged copy (same length, one byte flipped) fails verification and is fetched
    // again; the job still renders correctly.
    let mut damaged = glb.clone();
    let last = damaged.len() - 1;
    damaged[last] ^= 0xff;
    std::fs::write(&file, &damaged).unwrap();
    let job3 = create_job(&s, &c, &one).await;
    let w = TestWorker::start(&s.base, &cache, None);
    wait_until_done(&s, &c, job3.id).await;
    let summary = w.shutdown().await.unwrap();
    assert_eq!((summary.tasks_done, summary.scenes_downloaded), (8, 1));
    assert_eq!(std::fs::read(&file).unwrap(), glb);
    assert_eq!(
        frame_exr(&s, &c, job3.id, 2).await,
        direct_frame(&glb, &one, 2)
    );
    let (glbs, other) = cache_entries(&cache);
    assert_eq!((glbs.len(), other.len()), (1, 0), "{glbs:?} {other:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_new_scene_makes_room_by_removing_the_least_recently_used() {
    let Setup {
        dir,
        s,
        c,
        glb,
        scene,
    } = setup().await;
    let cache = dir.path().join("cache");
    std::fs::create_dir_all(&cache).unwrap();
    // Two scenes from earlier jobs, as large as this one, used a day and an hour ago.
    let now = std::time::SystemTime::now();
    let old: Vec<std::path::PathBuf> = [24 * 3600, 3600]
        .into_iter()
        .enumerate()
        .map(|(i, age)| {
            let bytes = vec![i as u8; glb.len()];
            let path = cache.join(format!("{}.glb", worker::cache::sha256_hex(&bytes)));
            std::fs::write(&path, &bytes).unwrap();
            let f = std::fs::File::options().write(true).open(&path).unwrap();
            f.set_modified(now - std::time::Duration::from_secs(age))
                .unwrap();
            path
        })
        .collect();

    // Room for two scenes: the new one pushes out the one used a day ago.
    let limit = 2 * glb.len() as u64 + glb.len() as u64 / 2;
    let job = create_job(&s, &c, &spec(&scene.digest, 1, 1, 1)).await;
    let w = TestWorker::start_config(worker::WorkerConfig {
        cache_limit_bytes: limit,
        ..worker_config(&s.base, &cache)
    });
    wait_until_done(&s, &c, job.id).await;
    let summary = w.shutdown().await.unwrap();
    assert_eq!(summary.scenes_downloaded, 1);
    assert!(!old[0].exists(), "the scene used a day ago is removed");
    assert!(old[1].exists(), "the scene used an hour ago stays");
    let file = cache.join(format!("{}.glb", scene.digest));
    assert_eq!(std::fs::read(&file).unwrap(), glb);
    let (glbs, other) = cache_entries(&cache);
    assert_eq!((glbs.len(), other.len()), (2, 0), "{glbs:?} {other:?}");
}
