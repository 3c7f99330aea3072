//! Snapshots of the emitted source: any change in generated code shows up as a
//! snapshot diff to review (`cargo insta review`).
#[test]
fn generated_sources() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../generated/src");
    for m in kinegen_generated::MODELS {
        let src = std::fs::read_to_string(dir.join(format!("{m}.rs"))).unwrap();
        insta::assert_snapshot!(*m, src);
    }
}
