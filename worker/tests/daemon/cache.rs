//! The scene cache: a scene is downloaded once per machine, and a corrupted cache file is
//! replaced by a fresh download.

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
