//! Derivation behind a trait. Nothing in this crate runs symbolica (so it may
//! use threads freely); a caller that needs a spec's IR that is not derived
//! yet (diagnosis's candidate effects, a benchmark's robots) asks a
//! [`Deriver`]. The command line's analysis deriver differentiates in-process
//! (`kinegen_model::autodiff`, any thread); a symbolic one runs `kinegen
//! derive` in a child process, as symbolica allows one thread per user and
//! machine.
use crate::effects::{with_chain, ApplyError, Effect};
use crate::model_on_log::model::ModelError;
use crate::model_on_log::model::Runner;
use kinegen_model::ir::ModelIr;
use kinegen_model::spec::Model;
use std::path::{Path, PathBuf};

/// Gives the IR of a validated model.
pub trait Deriver: Sync {
    /// The IR of `model`; `label` names the model in errors (a spec with
    /// effects added has no file of its own to name).
    fn derive(&self, model: &Model, label: &str) -> Result<ModelIr, DerivationFailed>;
}

/// A derivation that did not give an IR, in the deriver's words.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct DerivationFailed(pub String);

/// A spec with chains of catalogue effects added, as runners: what diagnosis
/// tries and what its report draws.
pub struct EffectChains<'a> {
    pub spec: &'a Model,
    pub catalogue: &'a [Effect],
    pub deriver: &'a dyn Deriver,
    /// The user's `--set` values, kept on every chain.
    pub sets: &'a [(String, f64)],
}

/// A chain of effects that gives no runner.
#[derive(Debug, thiserror::Error)]
pub enum ChainError {
    #[error(transparent)]
    Apply(#[from] ApplyError),
    #[error("could not be derived: {0} (`kinegen add-effect` writes that spec to read)")]
    Derive(DerivationFailed),
    #[error(transparent)]
    Runner(#[from] ModelError),
}

impl EffectChains<'_> {
    /// The runner of the spec with `effects` added in order (each at its
    /// nominal values).
    pub fn runner(&self, effects: &[String]) -> Result<Runner, ChainError> {
        let model = with_chain(self.spec, self.catalogue, effects)?;
        let label = format!(
            "{} with {} added",
            self.spec.path.display(),
            effects.join(", ")
        );
        let ir = self
            .deriver
            .derive(&model, &label)
            .map_err(ChainError::Derive)?;
        Ok(Runner::new(ir, self.sets)?)
    }
}

/// The analysis's [`Deriver`]: a bundled spec's committed IR when it is
/// current (the kernels `generate` emits, so the analysis and the embedded
/// code compute alike), else automatic differentiation in this process.
pub struct AutodiffDeriver;

impl Deriver for AutodiffDeriver {
    fn derive(&self, model: &Model, label: &str) -> Result<ModelIr, DerivationFailed> {
        let as_in_its_file = as_in_its_file(model);
        if as_in_its_file {
            if let Some(ir) = committed(&model.path, model) {
                return Ok(ir);
            }
        }
        kinegen_model::autodiff::derive(model, &Default::default()).map_err(|e| {
            DerivationFailed(if as_in_its_file {
                e.to_string()
            } else {
                // a spec with effects added has no file whose lines the
                // position could name: the label names it
                format!("{label}: {}", e.message)
            })
        })
    }
}

/// Where a spec's committed IR may be: `generated/ir/NAME.json` from the
/// working directory, or beside the spec's folder.
pub fn committed_candidates(spec: &Path, name: &str) -> Vec<PathBuf> {
    let mut v = vec![PathBuf::from("generated/ir").join(format!("{name}.json"))];
    if let Some(dir) = spec.parent() {
        v.push(dir.join("../generated/ir").join(format!("{name}.json")));
    }
    v
}

/// Whether `model` is its spec file as that file has it (not a model built
/// in memory, with effects added).
pub fn as_in_its_file(model: &Model) -> bool {
    std::fs::read_to_string(&model.path).is_ok_and(|text| text == model.source)
}

/// The committed IR of the spec at `spec`, when it is `model`'s.
pub fn committed(spec: &Path, model: &Model) -> Option<ModelIr> {
    let fp = model.fingerprint();
    committed_candidates(spec, &model.name)
        .into_iter()
        .find_map(|c| {
            let text = std::fs::read_to_string(&c).ok()?;
            ModelIr::from_json(&text)
                .ok()
                .filter(|ir| ir.spec_fingerprint == fp)
        })
}
