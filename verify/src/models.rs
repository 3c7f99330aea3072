//! The bundled models' IR, read from the generated crate's `ir/` directory.
use kinegen_model::ir::ModelIr;
use std::path::PathBuf;

pub fn ir_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../generated/ir")
}

/// The IR of a model of the generated crate.
pub fn load(model: &str) -> ModelIr {
    let path = ir_dir().join(format!("{model}.json"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    ModelIr::from_json(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Every model of the generated crate with its IR.
pub fn all() -> Vec<ModelIr> {
    kinegen_generated::MODELS.iter().map(|m| load(m)).collect()
}
