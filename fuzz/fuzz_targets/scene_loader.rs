//! Arbitrary bytes as an uploaded scene, through what `POST /api/v1/scenes` does with them:
//! the tracer's loader and the summary (`server::scene::inspect`), then the summary stored
//! as JSON and read back (job creation reads it). An error is fine; a panic, a hang or an
//! allocation out of proportion to the input is a finding (libFuzzer's -timeout and
//! -rss_limit_mb / -malloc_limit_mb, set by fuzz/run.sh).
#![no_main]

use libfuzzer_sys::fuzz_target;
use proto::SceneInfo;

fuzz_target!(|data: &[u8]| {
    // The route refuses an empty body before the loader sees it.
    if data.is_empty() {
        return;
    }
    let Ok((info, _scene)) = server::scene::inspect(data) else {
        return;
    };
    let json = serde_json::to_string(&info).expect("a scene summary serialises");
    let back: SceneInfo = serde_json::from_str(&json)
        .unwrap_or_else(|e| panic!("the stored summary does not read back ({e}): {json}"));
    assert_eq!(back, info, "the stored summary reads back different");
});
