//! Every WGSL file in shaders/ parses and validates with naga, on any machine (no GPU).

/// Shaders that are appended to another at load (the engine concatenates them the same way).
const APPENDED_TO: &[(&str, &str)] = &[("readback.wgsl", "raster.wgsl")];

#[test]
fn every_shader_validates() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders");
    let mut checked = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "wgsl") {
            continue;
        }
        let name = path.file_name().unwrap().to_str().unwrap();
        let mut source = std::fs::read_to_string(&path).unwrap();
        if let Some((_, base)) = APPENDED_TO.iter().find(|(n, _)| *n == name) {
            source = std::fs::read_to_string(dir.join(base)).unwrap() + &source;
        }
        let module = naga::front::wgsl::parse_str(&source)
            .unwrap_or_else(|e| panic!("{}: {}", path.display(), e.emit_to_string(&source)));
        naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::all(),
        )
        .validate(&module)
        .unwrap_or_else(|e| panic!("{}: {}", path.display(), e.emit_to_string(&source)));
        checked += 1;
    }
    assert!(checked >= 3, "expected the shaders in {}", dir.display());
}

#[test]
fn a_broken_shader_is_caught() {
    // The check above can fail: a type error is reported.
    let source = "@compute @workgroup_size(1) fn main() { let x: u32 = 1.5; }";
    let module = naga::front::wgsl::parse_str(source);
    let invalid = match module {
        Err(_) => true,
        Ok(m) => naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::all(),
        )
        .validate(&m)
        .is_err(),
    };
    assert!(invalid);
}
