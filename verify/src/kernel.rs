//! What is verified: a way to evaluate a model's functions by name.
use kinegen_model::ir::{Function, Kernel as KernelId, ModelIr, Op};

pub trait Kernel {
    /// Evaluate `f` (row-major output); false if this kernel lacks the function.
    fn eval(&self, f: &Function, args: &[&[f64]], out: &mut [f64]) -> bool;
    fn label(&self) -> String;
}

/// The IR evaluator: the tape interpreted (`fit` and `diagnose` run its
/// machine code, which kinegen-jit tests against it to the last bit).
pub struct IrKernel;

impl Kernel for IrKernel {
    fn eval(&self, f: &Function, args: &[&[f64]], out: &mut [f64]) -> bool {
        f.interpret_into(args, out, &mut Vec::new());
        true
    }
    fn label(&self) -> String {
        "IR evaluator".into()
    }
}

/// The compiled kernels of the `kinegen-generated` crate.
#[cfg(feature = "compiled")]
pub struct Generated(pub String);

#[cfg(feature = "compiled")]
impl Kernel for Generated {
    fn eval(&self, f: &Function, args: &[&[f64]], out: &mut [f64]) -> bool {
        kinegen_generated::call(&self.0, &f.name, args, out)
    }
    fn label(&self) -> String {
        format!("generated Rust ({})", self.0)
    }
}

/// A kernel with one deliberate mistake in one function: one term of one output
/// entry gets its sign flipped (the kind of slip a hand derivation makes). The
/// corrupted tape is what the emitter would turn into code.
pub struct Corrupted {
    pub kernel: KernelId,
    /// The corrupted kernel's name, for messages.
    pub function: String,
    pub tape: Vec<Op>,
    pub outputs: Vec<u32>,
}

impl Corrupted {
    /// Flip the sign of one term of output `entry` of `function`.
    pub fn flip_term(ir: &ModelIr, kernel: KernelId, entry: usize) -> Corrupted {
        let f = ir.kernel(kernel).expect("the model has the kernel");
        let mut tape = f.tape.clone();
        let mut outputs = f.outputs.clone();
        let slot = outputs[entry] as usize;
        match tape[slot] {
            Op::Add(a, b) => tape[slot] = Op::Sub(a, b),
            Op::Sub(a, b) => tape[slot] = Op::Add(a, b),
            _ => {
                tape.push(Op::Neg(slot as u32));
                outputs[entry] = (tape.len() - 1) as u32;
            }
        }
        Corrupted {
            kernel,
            function: f.name.clone(),
            tape,
            outputs,
        }
    }
}

impl Kernel for Corrupted {
    fn eval(&self, f: &Function, args: &[&[f64]], out: &mut [f64]) -> bool {
        if f.kernel == self.kernel {
            let g = Function {
                tape: self.tape.clone(),
                outputs: self.outputs.clone(),
                ..f.clone()
            };
            g.interpret_into(args, out, &mut Vec::new());
        } else {
            f.interpret_into(args, out, &mut Vec::new());
        }
        true
    }
    fn label(&self) -> String {
        format!("corrupted {}", self.function)
    }
}
