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
