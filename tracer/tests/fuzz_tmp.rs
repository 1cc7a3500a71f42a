use tracer::loader;
#[test]
fn fuzz_shared() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/scenes");
    for f in ["BoxTextured/BoxTextured.glb", "RiggedSimple/RiggedSimple.glb", "AnimatedMorphCube/AnimatedMorphCube.glb", "EmissiveStrengthTest/EmissiveStrengthTest.glb", "Cameras/Cameras.gltf", "TextureTransformTest/TextureTransformTest.gltf", "SimpleSkin/SimpleSkin.gltf", "InterpolationTest/InterpolationTest.glb"] {
        let path = dir.join(f);
        let good = if f.ends_with("gltf") { loader::pack_glb(&path).unwrap() } else { std::fs::read(&path).unwrap() };
        let json_end = 20 + u32::from_le_bytes(good[12..16].try_into().unwrap()) as usize;
        let digits: Vec<usize> = (20..json_end).filter(|&i| good[i].is_ascii_digit()).collect();
        let mut state = 0x2545_f491_u32;
        let mut next = || { state ^= state << 13; state ^= state >> 17; state ^= state << 5; state };
        let mut errs = std::collections::BTreeMap::new();
        for _ in 0..4000 {
            let mut bytes = good.clone();
            let k = 1 + next() % 3;
            for _ in 0..k {
                let at = next() as usize % json_end.min(bytes.len());
                match next() % 3 {
                    0 => bytes[at] = next() as u8,
                    1 => { let e = (at + 4).min(bytes.len()); bytes[at..e].fill(0xFF); }
                    _ => bytes[digits[next() as usize % digits.len()]] = b"0123456789"[next() as usize % 10],
                }
            }
            if let Err(e) = loader::load_glb(&bytes) {
                let s = e.to_string();
                let key: String = s.chars().take(30).collect();
                errs.entry(key).or_insert(s);
            }
        }
        println!("{f}: {} error kinds", errs.len());
        for (_, v) in errs.iter().take(12) { println!("   {v}"); }
    }
}
