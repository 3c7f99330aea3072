//! Machine code for a hot tape: the IR evaluator's fast path.
//!
//! Interpreting a tape costs a dispatch and a bounds-checked slot write per op,
//! 5-10x what the generated kernel costs, and fit and diagnose spend most of their
//! time evaluating tapes of specs that were never compiled (an edited spec, a
//! candidate effect). A tape is straight-line SSA code, which is exactly what
//! Cranelift takes, so [`Native::compile`] turns it into one native function with
//! the same arithmetic as the interpreter, op for op: the same integer-power
//! multiplication chain as `f64::powi`, the same libm calls, the same branch
//! selection for the series guards, the same pseudo-inverse helper. Results equal
//! the interpreter's to the last bit (tested below on every bundled tape).
//!
//! The IR (kinegen-model) is data: it interprets its own tapes and knows
//! nothing of this crate. An [`Evaluator`] (one function) or an [`IrCode`]
//! (every function of a model IR) keeps the compiled form in a
//! [`NativeCache`] beside the tape, compiles it once it has been evaluated
//! [`HOT_CALLS`] times, and keeps interpreting when compilation is
//! unavailable or switched off (`KINEGEN_JIT=0`).
//!
//! ```
//! use kinegen_jit::{Evaluator, HOT_CALLS};
//! use kinegen_model::ir::{Kernel, ModelIr, StepForm};
//!
//! let ir = ModelIr::from_json(include_str!("../../generated/ir/diff_drive.json")).unwrap();
//! let step = ir.kernel(Kernel::Step(StepForm::Exact, None)).unwrap();
//! // some value for every argument (pose, inputs, parameters, dt...)
//! let values: Vec<Vec<f64>> = step
//!     .args
//!     .iter()
//!     .map(|a| (0..a.names.len()).map(|i| 1.0 + 0.1 * i as f64).collect())
//!     .collect();
//! let args: Vec<&[f64]> = values.iter().map(|v| &v[..]).collect();
//! // interpreted until it is hot, then machine code: the same numbers
//! let fast = Evaluator::new(step.clone());
//! for _ in 0..=HOT_CALLS {
//!     assert_eq!(fast.eval(&args), step.interpret(&args));
//! }
//! ```

mod libm_sincos;

mod native;

use cranelift_codegen::ir::condcodes::FloatCC;
use cranelift_codegen::ir::{
    types, AbiParam, BlockArg, FuncRef, InstBuilder, MemFlagsData, StackSlot, StackSlotData,
    StackSlotKind, Value,
};
use cranelift_frontend::{FunctionBuilder, FunctionBuilderContext};
use cranelift_jit::{JITBuilder, JITModule};
use cranelift_module::{default_libcall_names, Linkage, Module};
use kinegen_model::ir::{Function, ModelIr, Op};
use kinegen_model::schedule::{schedule, Group, Item};
use native::Entry;
pub use native::{Native, NativeCache};
use std::collections::{HashMap, HashSet};
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex, OnceLock};

/// Interpreted calls before a tape is compiled: compiling costs about as much as
/// a few thousand interpreted calls, so one-off evaluations (a verification
/// probe, a single inverse) never pay for it.
pub const HOT_CALLS: u32 = 256;

impl Native {
    /// Evaluate into `out`; `None` (nothing written) when the argument or output
    /// lengths do not fit the tape, so the caller falls back to the interpreter
    /// (whose bounds checks then say what is wrong).
    #[inline]
    pub fn eval_into(&self, args: &[&[f64]], out: &mut [f64]) -> Option<()> {
        if args.len() != self.arg_len.len()
            || out.len() < self.outputs
            || args.iter().zip(&self.arg_len).any(|(a, n)| a.len() < *n)
        {
            return None;
        }
        const MAX_ARGS: usize = 16;
        let mut ptrs = [std::ptr::null::<f64>(); MAX_ARGS];
        for (p, a) in ptrs.iter_mut().zip(args) {
            *p = a.as_ptr();
        }
        // SAFETY: every argument holds at least the values the code reads
        // (checked above against `arg_len`), `out` at least `outputs` values.
        unsafe { (self.entry)(ptrs.as_ptr(), out.as_mut_ptr()) };
        Some(())
    }

    /// Compile `f`'s tape; `None` when the host has no Cranelift backend or the
    /// tape has more arguments than the entry point passes.
    pub fn compile(f: &Function) -> Option<Native> {
        if f.args.len() > 16 {
            return None;
        }
        let mut jb = JITBuilder::with_isa(host_isa()?, default_libcall_names());
        for (name, ptr, _) in host_functions() {
            jb.symbol(name, ptr);
        }
        let mut module = JITModule::new(jb);
        let entry_id = build(&mut module, f).ok()?;
        module.finalize_definitions().ok()?;
        let code = module.get_finalized_function(entry_id);
        let mut arg_len = vec![0usize; f.args.len()];
        for op in &f.tape {
            if let Op::Arg(a, i) = *op {
                arg_len[a as usize] = arg_len[a as usize].max(i as usize + 1);
            }
        }
        Some(Native {
            // SAFETY: `build` gave the function exactly the `Entry` signature.
            entry: unsafe { std::mem::transmute::<*const u8, Entry>(code) },
            arg_len,
            outputs: f.outputs.len(),
            module: Mutex::new(Some(module)),
        })
    }
}

/// The host's instruction set, `None` where Cranelift has no backend for it
/// (`JITBuilder::with_flags` would panic there).
fn host_isa() -> Option<cranelift_codegen::isa::OwnedTargetIsa> {
    use cranelift_codegen::settings::{self, Configurable};
    let mut flags = settings::builder();
    flags.set("opt_level", "speed").ok()?;
    // as `JITBuilder::with_flags` sets them: calls to host functions anywhere
    flags.set("use_colocated_libcalls", "false").ok()?;
    flags.set("is_pic", "false").ok()?;
    let isa = cranelift_native::builder().ok()?;
    isa.finish(settings::Flags::new(flags)).ok()
}

impl NativeCache {
    /// The compiled tape once `f` is hot, compiling it on the call that makes it so.
    #[inline]
    pub fn get(&self, f: &Function) -> Option<&Native> {
        let code = match self.code.get() {
            Some(code) => code,
            None => {
                if !enabled() || self.calls.fetch_add(1, Ordering::Relaxed) < HOT_CALLS {
                    return None;
                }
                self.code.get_or_init(|| compiled(f))
            }
        };
        code.as_deref()
    }
}

/// Evaluate `f` into `out` (length rows*cols, row-major) with the machine
/// code `cache` holds for it once it is hot, else by interpreting its tape
/// (`scratch` is reused between calls). Both give the same results to the
/// last bit.
#[inline]
pub fn eval_into(
    f: &Function,
    cache: &NativeCache,
    args: &[&[f64]],
    out: &mut [f64],
    scratch: &mut Vec<f64>,
) {
    if let Some(native) = cache.get(f) {
        if native.eval_into(args, out).is_some() {
            return;
        }
    }
    f.interpret_into(args, out, scratch)
}

/// A function with its machine code: one the analysis builds itself (a
/// fused step) and evaluates in its loops. Derefs to the function.
#[derive(Debug, Clone)]
pub struct Evaluator {
    f: Function,
    cache: NativeCache,
}

impl Evaluator {
    pub fn new(f: Function) -> Evaluator {
        Evaluator {
            f,
            cache: NativeCache::default(),
        }
    }

    /// Evaluate into `out` (see [`eval_into`]).
    #[inline]
    pub fn eval_into(&self, args: &[&[f64]], out: &mut [f64], scratch: &mut Vec<f64>) {
        eval_into(&self.f, &self.cache, args, out, scratch)
    }

    /// Evaluate into a new vector.
    pub fn eval(&self, args: &[&[f64]]) -> Vec<f64> {
        let mut out = vec![0.0; self.f.rows * self.f.cols];
        self.eval_into(args, &mut out, &mut Vec::new());
        out
    }
}

impl std::ops::Deref for Evaluator {
    type Target = Function;
    fn deref(&self) -> &Function {
        &self.f
    }
}

/// The machine code of every function of one model IR, kept beside it (the
/// IR stays data): the functions are found by reference into that IR, so
/// the analysis passes `&ir.functions()[k]` as it reads it.
#[derive(Debug, Clone, Default)]
pub struct IrCode {
    caches: Vec<NativeCache>,
}

impl IrCode {
    pub fn new(ir: &ModelIr) -> IrCode {
        IrCode {
            caches: ir
                .functions()
                .iter()
                .map(|_| NativeCache::default())
                .collect(),
        }
    }

    /// The cache of `f` when it is one of `ir`'s functions (by address: a
    /// function from elsewhere, or a copy, is interpreted).
    #[inline]
    fn cache(&self, ir: &ModelIr, f: &Function) -> Option<&NativeCache> {
        let all = ir.functions();
        let size = std::mem::size_of::<Function>();
        let offset = (f as *const Function as usize).checked_sub(all.as_ptr() as usize)?;
        let i = offset / size;
        (offset % size == 0 && i < all.len() && std::ptr::eq(&all[i], f))
            .then(|| self.caches.get(i))
            .flatten()
    }

    /// Evaluate `f`, a function of `ir`, into `out` (see [`eval_into`]).
    #[inline]
    pub fn eval_into(
        &self,
        ir: &ModelIr,
        f: &Function,
        args: &[&[f64]],
        out: &mut [f64],
        scratch: &mut Vec<f64>,
    ) {
        match self.cache(ir, f) {
            Some(cache) => eval_into(f, cache, args, out, scratch),
            None => f.interpret_into(args, out, scratch),
        }
    }
}

/// A compiled tape with what it was compiled from.
struct Compiled {
    tape: Vec<Op>,
    outputs: Vec<u32>,
    args: usize,
    native: Option<Arc<Native>>,
}

/// `f` compiled, once per distinct tape in this process: diagnosis clones a
/// runner for every candidate fit, and each clone's tapes are the same code.
/// Entries are found by a hash of the tape and confirmed by comparing it whole,
/// so an edited tape never runs another's code.
fn compiled(f: &Function) -> Option<Arc<Native>> {
    static ALL: OnceLock<Mutex<HashMap<u64, Vec<Compiled>>>> = OnceLock::new();
    let key = tape_hash(f);
    let same = |e: &Compiled| e.tape == f.tape && e.outputs == f.outputs && e.args == f.args.len();
    let all = ALL.get_or_init(Default::default);
    if let Some(e) = all
        .lock()
        .ok()?
        .get(&key)
        .and_then(|v| v.iter().find(|e| same(e)))
    {
        return e.native.clone();
    }
    // compiled outside the lock: another thread compiling the same tape at once
    // costs one redundant compilation, not a wait
    let native = Native::compile(f).map(Arc::new);
    all.lock().ok()?.entry(key).or_default().push(Compiled {
        tape: f.tape.clone(),
        outputs: f.outputs.clone(),
        args: f.args.len(),
        native: native.clone(),
    });
    native
}

/// A hash of the tape, outputs and argument count (the Debug text of each op
/// is exact: floats print in their shortest round-trip form).
fn tape_hash(f: &Function) -> u64 {
    use std::fmt::Write;
    use std::hash::Hasher;
    struct Feed(std::collections::hash_map::DefaultHasher);
    impl Write for Feed {
        fn write_str(&mut self, s: &str) -> std::fmt::Result {
            self.0.write(s.as_bytes());
            Ok(())
        }
    }
    let mut h = Feed(Default::default());
    for op in &f.tape {
        let _ = write!(h, "{op:?};");
    }
    let _ = write!(h, "{:?}/{}", f.outputs, f.args.len());
    h.0.finish()
}

/// Compilation is on unless `KINEGEN_JIT=0` (benchmarks compare both).
fn enabled() -> bool {
    static ON: OnceLock<bool> = OnceLock::new();
    *ON.get_or_init(|| std::env::var("KINEGEN_JIT").map_or(true, |v| v != "0"))
}

extern "C" fn host_tan(x: f64) -> f64 {
    x.tan()
}
extern "C" fn host_atan(x: f64) -> f64 {
    x.atan()
}
extern "C" fn host_exp(x: f64) -> f64 {
    x.exp()
}
extern "C" fn host_ln(x: f64) -> f64 {
    x.ln()
}
extern "C" fn host_atan2(y: f64, x: f64) -> f64 {
    y.atan2(x)
}
extern "C" fn host_pow(x: f64, y: f64) -> f64 {
    x.powf(y)
}
/// Both `sin x` and `cos x` from libm's `sincos` (bit for bit `libm::sin` and
/// `libm::cos`), into the 2 values at `out`: the cold path of the inline
/// [`libm_sincos`] for arguments beyond 2^20 pi/2, infinities and NaN.
///
/// # Safety
/// `out` points at 2 values (a stack slot of the compiled code).
unsafe extern "C" fn host_sincos(x: f64, out: *mut f64) {
    let (sin, cos) = libm::sincos(x);
    unsafe { std::slice::from_raw_parts_mut(out, 2) }.copy_from_slice(&[sin, cos]);
}
/// The packed pseudo-inverse of the packed symmetric 3x3 matrix at `m`.
///
/// # Safety
/// `m` and `out` point at 6 values each (stack slots of the compiled code).
unsafe extern "C" fn host_pinv_sym3(m: *const f64, out: *mut f64) {
    let m = unsafe { std::slice::from_raw_parts(m, 6) };
    let p = kinegen_model::linalg::pinv_sym3([m[0], m[1], m[2], m[3], m[4], m[5]]);
    unsafe { std::slice::from_raw_parts_mut(out, 6) }.copy_from_slice(&p);
}

/// How a host function is called from compiled code.
#[derive(Clone, Copy)]
enum HostSig {
    /// n f64 operands, one f64 result.
    Math(usize),
    /// (f64, pointer to the 2 results): sin and cos together.
    SinCos,
    /// (pointer to the 6 packed inputs, pointer to the 6 packed results).
    PinvSym3,
}

/// Every host function the compiled code may call: its symbol, address and
/// signature (one table serves the JIT's symbol table and the declarations).
fn host_functions() -> [(&'static str, *const u8, HostSig); 8] {
    use HostSig::*;
    [
        ("kg_sincos", host_sincos as *const u8, SinCos),
        ("kg_tan", host_tan as *const u8, Math(1)),
        ("kg_atan", host_atan as *const u8, Math(1)),
        ("kg_exp", host_exp as *const u8, Math(1)),
        ("kg_ln", host_ln as *const u8, Math(1)),
        ("kg_atan2", host_atan2 as *const u8, Math(2)),
        ("kg_pow", host_pow as *const u8, Math(2)),
        ("kg_pinv_sym3", host_pinv_sym3 as *const u8, PinvSym3),
    ]
}

type CompileError = Box<cranelift_module::ModuleError>;

/// Translate the tape into the module as the exported entry point, in the order
/// and branches of [`schedule`]: the two sides of a series guard are real
/// branches, so only the side taken is computed (as in the generated kernels).
fn build(module: &mut JITModule, f: &Function) -> Result<cranelift_module::FuncId, CompileError> {
    let ptr = module.target_config().pointer_type();
    let mut ctx = module.make_context();
    ctx.func.signature.params.push(AbiParam::new(ptr));
    ctx.func.signature.params.push(AbiParam::new(ptr));
    let mut imports = HashMap::new();
    for (name, _, host_sig) in host_functions() {
        let mut sig = module.make_signature();
        let (f64p, ptrp) = (AbiParam::new(types::F64), AbiParam::new(ptr));
        match host_sig {
            HostSig::Math(n) => {
                sig.params.extend((0..n).map(|_| f64p));
                sig.returns.push(f64p);
            }
            HostSig::SinCos => sig.params.extend([f64p, ptrp]),
            HostSig::PinvSym3 => sig.params.extend([ptrp, ptrp]),
        }
        imports.insert(name, module.declare_function(name, Linkage::Import, &sig)?);
    }

    let mut fctx = FunctionBuilderContext::new();
    let mut b = FunctionBuilder::new(&mut ctx.func, &mut fctx);
    let block = b.create_block();
    b.append_block_params_for_function_params(block);
    b.switch_to_block(block);
    b.seal_block(block);
    let (args_ptr, out_ptr) = (b.block_params(block)[0], b.block_params(block)[1]);
    let arg_bases: Vec<Value> = (0..f.args.len())
        .map(|a| b.ins().load(ptr, MEM, args_ptr, (a * 8) as i32))
        .collect();
    let host: HashMap<&str, FuncRef> = imports
        .iter()
        .map(|(name, id)| (*name, module.declare_func_in_func(*id, b.func)))
        .collect();
    let (pinv, sincos) = (host["kg_pinv_sym3"], host["kg_sincos"]);
    let (items, groups) = schedule(&f.tape, &f.outputs);
    let both = sin_cos_pairs(&f.tape, &items);
    let mut t = Translator {
        b,
        tape: &f.tape,
        groups: &groups,
        ptr,
        arg_bases,
        host,
        pinv,
        pinv_out: HashMap::new(),
        sincos,
        both,
        sincos_of: HashMap::new(),
        slots: vec![None; f.tape.len()],
        out_ptr,
        unstored: HashMap::new(),
    };
    for (k, &s) in f.outputs.iter().enumerate() {
        t.unstored.entry(s as usize).or_default().push(k);
    }
    t.items(&items);
    // outputs no item computes (arguments) or computed inside a guard's merge
    let mut rest: Vec<usize> = t.unstored.keys().copied().collect();
    rest.sort();
    for s in rest {
        let v = t.v(s as u32);
        t.store_if_output(s, v);
    }
    t.b.ins().return_(&[]);
    t.b.finalize(module.target_config());
    let id = module.declare_function("tape", Linkage::Export, &ctx.func.signature)?;
    module.define_function(id, &mut ctx)?;
    module.clear_context(&mut ctx);
    Ok(id)
}

/// The tape reads its arguments and writes its outputs only through the entry
/// point's pointers, aligned and valid (checked by [`Native::eval_into`]).
const MEM: MemFlagsData = MemFlagsData::trusted();

/// One tape being translated: the value of every slot emitted so far.
struct Translator<'a, 'f> {
    b: FunctionBuilder<'f>,
    tape: &'a [Op],
    groups: &'a [Group],
    ptr: types::Type,
    arg_bases: Vec<Value>,
    host: HashMap<&'static str, FuncRef>,
    pinv: FuncRef,
    /// One decomposition per distinct matrix, read entry by entry (as the
    /// interpreter's cache does).
    pinv_out: HashMap<[u32; 6], StackSlot>,
    sincos: FuncRef,
    /// Slots whose sine and cosine are both taken in one scope: one host call.
    both: HashSet<u32>,
    /// (sin, cos) of such a slot, once the first of the two is emitted.
    sincos_of: HashMap<u32, (Value, Value)>,
    slots: Vec<Option<Value>>,
    out_ptr: Value,
    /// Output positions of each slot not yet stored. An output is stored as
    /// soon as it is computed, so its register is free for the rest of the
    /// tape instead of being held (or spilled) until the end.
    unstored: HashMap<usize, Vec<usize>>,
}

/// The slots whose sine and cosine the tape takes in the same scope of the
/// schedule (the body, or one side of one guard): computed together there, the
/// first of the two dominates the second. A pair split across scopes stays two
/// calls, so no side computes a value it does not need.
fn sin_cos_pairs(tape: &[Op], items: &[Item]) -> HashSet<u32> {
    fn walk(
        tape: &[Op],
        items: &[Item],
        scope: usize,
        next: &mut usize,
        seen: &mut HashMap<(u32, bool), usize>,
    ) {
        for item in items {
            match item {
                Item::Slot(s) => match tape[*s] {
                    Op::Sin(x) => {
                        seen.insert((x, true), scope);
                    }
                    Op::Cos(x) => {
                        seen.insert((x, false), scope);
                    }
                    _ => {}
                },
                Item::Guard { near, far, .. } => {
                    for side in [near, far] {
                        *next += 1;
                        walk(tape, side, *next, next, seen);
                    }
                }
            }
        }
    }
    let mut seen = HashMap::new();
    walk(tape, items, 0, &mut 0, &mut seen);
    seen.iter()
        .filter(|((x, is_sin), scope)| *is_sin && seen.get(&(*x, false)) == Some(scope))
        .map(|((x, _), _)| *x)
        .collect()
}

impl Translator<'_, '_> {
    /// The value of slot `s` for a use about to be emitted. An argument is
    /// loaded again at each use, where it is needed: loaded once at the top, every
    /// argument would stay live across the whole tape and its host calls, and be
    /// spilled to the stack and reloaded anyway (LLVM rematerialises such loads
    /// in the generated kernels; Cranelift's register allocator does not).
    fn v(&mut self, s: u32) -> Value {
        if let Op::Arg(a, i) = self.tape[s as usize] {
            let base = self.arg_bases[a as usize];
            return self.b.ins().load(types::F64, MEM, base, i as i32 * 8);
        }
        self.slots[s as usize].expect("the schedule emits every operand before its reader")
    }

    /// Stores `v` at every output position of slot `s` not yet stored.
    fn store_if_output(&mut self, s: usize, v: Value) {
        for k in self.unstored.remove(&s).unwrap_or_default() {
            self.b.ins().store(MEM, v, self.out_ptr, k as i32 * 8);
        }
    }

    fn items(&mut self, items: &[Item]) {
        for item in items {
            match item {
                // loaded at each use instead (`v`)
                Item::Slot(s) if matches!(self.tape[*s], Op::Arg(..)) => {}
                Item::Slot(s) => {
                    let v = self.op(*s);
                    self.slots[*s] = Some(v);
                    self.store_if_output(*s, v);
                }
                Item::Guard { group, near, far } => self.guard(*group, near, far),
            }
        }
    }

    /// `if |x| < eps { near side } else { far side }`, binding every member of the
    /// group from the side taken. |x| < eps is false for NaN: the far side, as
    /// the interpreter's `NearZero`.
    fn guard(&mut self, group: usize, near: &[Item], far: &[Item]) {
        let g = &self.groups[group];
        let x = self.v(g.x);
        let ax = self.b.ins().fabs(x);
        let eps = self.b.ins().f64const(g.eps);
        let is_near = self.b.ins().fcmp(FloatCC::LessThan, ax, eps);
        let (near_block, far_block, merge) = (
            self.b.create_block(),
            self.b.create_block(),
            self.b.create_block(),
        );
        for _ in &g.members {
            self.b.append_block_param(merge, types::F64);
        }
        self.b.ins().brif(is_near, near_block, &[], far_block, &[]);
        for (block, side, is_near_side) in [(near_block, near, true), (far_block, far, false)] {
            self.b.switch_to_block(block);
            self.b.seal_block(block);
            self.items(side);
            let values: Vec<BlockArg> = self.groups[group]
                .members
                .iter()
                .map(|&m| match self.tape[m] {
                    Op::NearZero { near, far, .. } => {
                        BlockArg::Value(self.v(if is_near_side { near } else { far }))
                    }
                    _ => unreachable!("a guard group holds NearZero slots"),
                })
                .collect();
            self.b.ins().jump(merge, &values);
        }
        self.b.switch_to_block(merge);
        self.b.seal_block(merge);
        for (k, &m) in self.groups[group].members.iter().enumerate() {
            self.slots[m] = Some(self.b.block_params(merge)[k]);
        }
    }

    /// The value of slot `s`, computed from its operands.
    fn op(&mut self, s: usize) -> Value {
        if let Op::PinvSym3 { m, i, j } = self.tape[s] {
            let out = match self.pinv_out.get(&m) {
                Some(slot) => *slot,
                None => self.decompose(m),
            };
            let k = kinegen_model::linalg::packed_index(i as usize, j as usize);
            return self
                .b
                .ins()
                .stack_load(self.ptr, types::F64, out, k as i32 * 8);
        }
        // this op's argument operands, loaded here for it alone: the emission
        // below reads operands from `slots` while it holds the builder
        for o in self.tape[s].operands() {
            if matches!(self.tape[o as usize], Op::Arg(..)) {
                self.slots[o as usize] = Some(self.v(o));
            }
        }
        match self.tape[s] {
            Op::Sin(x) => return self.sin_cos(x, self.both.contains(&x)).0,
            Op::Cos(x) => return self.sin_cos(x, self.both.contains(&x)).1,
            _ => {}
        }
        let (slots, host, b) = (&self.slots, &self.host, &mut self.b);
        let v =
            |i: u32| slots[i as usize].expect("the schedule emits every operand before its reader");
        let mut call = |name: &str, xs: &[Value]| {
            let inst = b.ins().call(host[name], xs);
            b.inst_results(inst)[0]
        };
        match self.tape[s] {
            Op::Pow(x, y) => return call("kg_pow", &[v(x), v(y)]),
            Op::Tan(x) => return call("kg_tan", &[v(x)]),
            Op::Atan(x) => return call("kg_atan", &[v(x)]),
            Op::Atan2(y, x) => return call("kg_atan2", &[v(y), v(x)]),
            Op::Exp(x) => return call("kg_exp", &[v(x)]),
            Op::Ln(x) => return call("kg_ln", &[v(x)]),
            _ => {}
        }
        match self.tape[s] {
            Op::Const(c) => b.ins().f64const(c),
            Op::Arg(a, i) => {
                b.ins()
                    .load(types::F64, MEM, self.arg_bases[a as usize], i as i32 * 8)
            }
            Op::Add(x, y) => b.ins().fadd(v(x), v(y)),
            Op::Sub(x, y) => b.ins().fsub(v(x), v(y)),
            Op::Mul(x, y) => b.ins().fmul(v(x), v(y)),
            Op::Div(x, y) => b.ins().fdiv(v(x), v(y)),
            Op::Neg(x) => b.ins().fneg(v(x)),
            Op::PowI(x, n) => powi(b, v(x), n),
            Op::Sqrt(x) => b.ins().sqrt(v(x)),
            Op::Abs(x) => b.ins().fabs(v(x)),
            Op::Sign(x) => sign(b, v(x)),
            Op::NearZero { .. } => unreachable!("guards are emitted as groups"),
            _ => unreachable!("host calls and the pseudo-inverse are handled above"),
        }
    }

    /// The sine and cosine of slot `x`, as libm's `sincos` computes them:
    /// inline for |x| < 2^20 pi/2, from a host call on a cold path beyond. A
    /// call clobbers every SSE register, so each call on the hot path spilled
    /// every value live across it (the generated kernels inline libm too).
    /// `shared`: the pair is kept for the other of the two ops (both are in
    /// this scope, see [`sin_cos_pairs`]).
    fn sin_cos(&mut self, x: u32, shared: bool) -> (Value, Value) {
        if let Some(&pair) = self.sincos_of.get(&x) {
            return pair;
        }
        let arg = self.v(x);
        let (ptr, host) = (self.ptr, self.sincos);
        let pair = libm_sincos::emit(&mut self.b, arg, |b, arg| {
            let out =
                b.create_sized_stack_slot(StackSlotData::new(StackSlotKind::ExplicitSlot, 16, 3));
            let addr = b.ins().stack_addr(ptr, out, 0);
            b.ins().call(host, &[arg, addr]);
            let sin = b.ins().stack_load(ptr, types::F64, out, 0);
            let cos = b.ins().stack_load(ptr, types::F64, out, 8);
            (sin, cos)
        });
        if shared {
            self.sincos_of.insert(x, pair);
        }
        pair
    }

    /// The pseudo-inverse of the packed matrix in slots `m`; returns the stack
    /// slot holding its 6 packed entries. The well-conditioned case (nearly
    /// every call: a least-squares twist of a robot that can move) is the
    /// cofactor inverse of `linalg::inverse_well_conditioned`, emitted inline
    /// with the same operations in the same order (so the same bits); the
    /// rank-deficient rest calls the host's eigen-decomposition. The host
    /// call (matrix and result through memory) took about a quarter of the
    /// compiled tapes' time in a profile of omni_caster's diagnosis.
    fn decompose(&mut self, m: [u32; 6]) -> StackSlot {
        let packed6 = StackSlotData::new(StackSlotKind::ExplicitSlot, 48, 3);
        let out = self.b.create_sized_stack_slot(packed6.clone());
        let [a, b_, c, d, e, f] = m.map(|s| self.v(s));
        let (ptr, pinv) = (self.ptr, self.pinv);
        let b = &mut self.b;
        let sub_of_products = |b: &mut FunctionBuilder, w: Value, x: Value, y: Value, z: Value| {
            let (p, q) = (b.ins().fmul(w, x), b.ins().fmul(y, z));
            b.ins().fsub(p, q)
        };
        // [[a b c] [b d e] [c e f]]
        let c00 = sub_of_products(b, d, f, e, e);
        let c01 = sub_of_products(b, c, e, b_, f);
        let c02 = sub_of_products(b, b_, e, c, d);
        let (ac, bc, cc) = (
            b.ins().fmul(a, c00),
            b.ins().fmul(b_, c01),
            b.ins().fmul(c, c02),
        );
        let det = b.ins().fadd(ac, bc);
        let det = b.ins().fadd(det, cc);
        let trace = b.ins().fadd(a, d);
        let trace = b.ins().fadd(trace, f);
        let k = b.ins().f64const(kinegen_model::linalg::WELL_CONDITIONED);
        let bound = b.ins().fmul(k, trace);
        let bound = b.ins().fmul(bound, trace);
        let bound = b.ins().fmul(bound, trace);
        let zero = b.ins().f64const(0.0);
        // false for NaN, as the host's test: the eigen-decomposition decides
        let positive = b.ins().fcmp(FloatCC::GreaterThan, trace, zero);
        let above = b.ins().fcmp(FloatCC::GreaterThan, det, bound);
        let well = b.ins().band(positive, above);
        let (inline, host, merge) = (b.create_block(), b.create_block(), b.create_block());
        b.ins().brif(well, inline, &[], host, &[]);

        b.switch_to_block(inline);
        b.seal_block(inline);
        let one = b.ins().f64const(1.0);
        let r = b.ins().fdiv(one, det);
        let c11 = sub_of_products(b, a, f, c, c);
        let c12 = sub_of_products(b, b_, c, a, e);
        let c22 = sub_of_products(b, a, d, b_, b_);
        for (k, x) in [c00, c01, c02, c11, c12, c22].into_iter().enumerate() {
            let y = b.ins().fmul(x, r);
            b.ins().stack_store(ptr, y, out, k as i32 * 8);
        }
        b.ins().jump(merge, &[]);

        b.switch_to_block(host);
        b.seal_block(host);
        let input = b.create_sized_stack_slot(packed6);
        for (k, x) in [a, b_, c, d, e, f].into_iter().enumerate() {
            b.ins().stack_store(ptr, x, input, k as i32 * 8);
        }
        let pi = b.ins().stack_addr(ptr, input, 0);
        let po = b.ins().stack_addr(ptr, out, 0);
        b.ins().call(pinv, &[pi, po]);
        b.ins().jump(merge, &[]);

        b.switch_to_block(merge);
        b.seal_block(merge);
        self.pinv_out.insert(m, out);
        out
    }
}

/// -1, 0 or 1 as [`kinegen_model::ir::sign`]: two comparisons and selects, and
/// `x * 0` where neither holds (0 for +-0, NaN for NaN).
fn sign(b: &mut FunctionBuilder, x: Value) -> Value {
    let zero = b.ins().f64const(0.0);
    let (one, minus) = (b.ins().f64const(1.0), b.ins().f64const(-1.0));
    let rest = b.ins().fmul(x, zero);
    let neg = b.ins().fcmp(FloatCC::LessThan, x, zero);
    let not_pos = b.ins().select(neg, minus, rest);
    let pos = b.ins().fcmp(FloatCC::GreaterThan, x, zero);
    b.ins().select(pos, one, not_pos)
}

/// `x^n` by the multiplication chain `f64::powi` uses (compiler-rt's `__powidf2`:
/// square-and-multiply from the low bit, then one reciprocal for n < 0), so the
/// compiled tape rounds exactly as the interpreter does.
fn powi(b: &mut FunctionBuilder, x: Value, n: i32) -> Value {
    let mut e = n.unsigned_abs();
    let mut base = x;
    let mut r: Option<Value> = None;
    loop {
        if e & 1 == 1 {
            r = Some(match r {
                Some(r) => b.ins().fmul(r, base),
                None => base,
            });
        }
        e /= 2;
        if e == 0 {
            break;
        }
        base = b.ins().fmul(base, base);
    }
    let r = r.unwrap_or_else(|| b.ins().f64const(1.0));
    if n < 0 {
        let one = b.ins().f64const(1.0);
        b.ins().fdiv(one, r)
    } else {
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kinegen_model::ir::{ArgRole, ArgSpec, Kernel};

    fn function(tape: Vec<Op>, outputs: Vec<u32>, args: usize) -> Function {
        const ROLES: [ArgRole; 4] = [
            ArgRole::State,
            ArgRole::Inputs,
            ArgRole::Noise,
            ArgRole::Params,
        ];
        Function {
            kernel: Kernel::Fused,
            name: "t".into(),
            doc: String::new(),
            args: (0..args)
                .map(|a| ArgSpec {
                    role: ROLES[a],
                    names: vec!["v".into(); 3],
                })
                .collect(),
            rows: outputs.len(),
            cols: 1,
            row_names: vec![],
            col_names: vec![],
            tape,
            outputs,
            ops_tree: 0,
        }
    }

    #[test]
    fn every_op_matches_the_interpreter_to_the_bit() {
        let mut tape = vec![Op::Arg(0, 0), Op::Arg(0, 1), Op::Arg(1, 0)];
        let unary = [
            Op::Neg(0),
            Op::Sqrt(1),
            Op::Sin(0),
            Op::Cos(0),
            Op::Tan(0),
            Op::Atan(0),
            Op::Exp(0),
            Op::Ln(1),
            Op::Abs(0),
            Op::Sign(0),
            Op::Sign(2),
        ];
        tape.extend(unary);
        tape.extend([
            Op::Add(0, 1),
            Op::Sub(0, 1),
            Op::Mul(0, 2),
            Op::Div(0, 2),
            Op::Pow(1, 2),
            Op::Atan2(0, 1),
            Op::Const(0.25),
        ]);
        for n in [-7, -2, -1, 0, 1, 2, 3, 5, 8, 13] {
            tape.push(Op::PowI(0, n));
        }
        let near = tape.len() as u32 - 1;
        tape.push(Op::NearZero {
            x: 0,
            eps: 1e-3,
            near,
            far: 3,
        });
        // a positive definite packed matrix and two of its inverse's entries
        tape.extend([Op::Mul(1, 1), Op::Const(0.1)]);
        let (d, o) = (tape.len() as u32 - 2, tape.len() as u32 - 1);
        tape.push(Op::PinvSym3 {
            m: [d, o, o, d, o, d],
            i: 0,
            j: 1,
        });
        tape.push(Op::PinvSym3 {
            m: [d, o, o, d, o, d],
            i: 2,
            j: 2,
        });
        // well conditioned for some x, indefinite at x = 0 and rank one at
        // every x: the compiled code's inline inverse and its host call
        tape.push(Op::Mul(0, 0));
        let z = tape.len() as u32 - 1;
        for (m, i, j) in [([d, o, o, d, o, z], 1, 2), ([o, o, o, o, o, o], 0, 0)] {
            tape.push(Op::PinvSym3 { m, i, j });
        }
        let outputs: Vec<u32> = (0..tape.len() as u32).collect();
        let f = function(tape, outputs, 2);
        let native = Native::compile(&f).expect("this host has a Cranelift backend");
        for x in [-1.7, -1e-4, 0.0, 3e-4, 0.6, 2.5] {
            let args: [&[f64]; 2] = [&[x, 1.3 + x.abs()], &[0.8]];
            let mut got = vec![0.0; f.outputs.len()];
            native.eval_into(&args, &mut got).unwrap();
            let mut want = vec![0.0; f.outputs.len()];
            f.interpret_into(&args, &mut want, &mut Vec::new());
            for (k, (g, w)) in got.iter().zip(&want).enumerate() {
                assert!(
                    g.to_bits() == w.to_bits() || (g.is_nan() && w.is_nan()),
                    "x = {x}, slot {k} ({:?}): compiled {g:e}, interpreted {w:e}",
                    f.tape[k]
                );
            }
        }
    }

    #[test]
    fn sine_and_cosine_are_libms_to_the_bit_on_every_branch() {
        // sin x, cos x (one inline sincos) and cos 2x alone
        let tape = vec![
            Op::Arg(0, 0),
            Op::Sin(0),
            Op::Cos(0),
            Op::Add(0, 0),
            Op::Cos(3),
        ];
        let f = function(tape, vec![1, 2, 4], 1);
        let native = Native::compile(&f).expect("this host has a Cranelift backend");
        let pi_2 = std::f64::consts::FRAC_PI_2;
        // every boundary of libm's branches, and the multiples of pi/2 where
        // one round of reduction cancels, each with its neighbours
        let mut xs: Vec<f64> = vec![
            0.0,
            1e-300,
            5e-324,
            1e-9,
            1e-8,
            0.5,
            1.0,
            2.0,
            3.0,
            6.0,
            7.5,
            10.0,
            100.0,
            12345.678,
            1.6e6,
            1.7e6,
            1e9,
            1e300,
            f64::INFINITY,
            f64::NAN,
            f64::MIN_POSITIVE,
        ];
        for high in [
            0x3e46_a09e_u64,
            0x3e50_0000,
            0x3fe9_21fb,
            0x4002_d97c,
            0x400f_6a7a,
        ]
        .into_iter()
        .chain([
            0x4012_d97c,
            0x4015_fdbc,
            0x4019_21fb,
            0x401c_463b,
            0x4139_21fb,
        ]) {
            for h in [high - 1, high, high + 1] {
                for low in [0, 1, 0x1234_5678, 0x7fff_ffff, 0xffff_ffff] {
                    xs.push(f64::from_bits(h << 32 | low));
                }
            }
        }
        xs.extend((1..=400).map(|k| k as f64 * pi_2 / 2.0));
        // near multiples of pi/2, the first round cancelling 10 to 60 bits: the
        // second and third rounds and their thresholds
        for m in [1.0, 2.0, 3.0, 4.0, 5.0, 17.0, 7919.0, 104_729.0, 600_000.0] {
            for j in 10..=60 {
                xs.push(m * pi_2 * (1.0 + (-j as f64).exp2()));
                xs.push(m * pi_2 * (1.0 - (-j as f64).exp2()));
            }
        }
        let mut rng = 0x2545_f491_4f6c_dd1d_u64;
        xs.extend((0..20_000).map(|_| {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            // log-uniform magnitudes from 1e-10 to 1e7
            let u = (rng >> 11) as f64 / (1u64 << 53) as f64;
            10f64.powf(-10.0 + 17.0 * u)
        }));
        let near: Vec<f64> = xs
            .iter()
            .flat_map(|&x| {
                let (up, down) = (
                    f64::from_bits(x.to_bits() + 1),
                    f64::from_bits(x.to_bits().saturating_sub(1)),
                );
                [x, up, down]
            })
            .collect();
        for x in near.iter().flat_map(|&x| [x, -x]) {
            let mut got = [0.0; 3];
            native.eval_into(&[&[x]], &mut got).unwrap();
            let want = [libm::sin(x), libm::cos(x), libm::cos(x + x)];
            for (k, (g, w)) in got.iter().zip(&want).enumerate() {
                assert!(
                    g.to_bits() == w.to_bits() || (g.is_nan() && w.is_nan()),
                    "x = {x:e} ({:#x}), output {k}: compiled {g:e}, libm {w:e}",
                    x.to_bits()
                );
            }
        }
    }

    #[test]
    fn short_arguments_or_output_are_refused_not_read() {
        let f = function(vec![Op::Arg(0, 2), Op::Arg(1, 0)], vec![0, 1], 2);
        let native = Native::compile(&f).unwrap();
        let mut out = [0.0; 2];
        assert!(native.eval_into(&[&[1.0, 2.0], &[1.0]], &mut out).is_none());
        assert!(native.eval_into(&[&[1.0, 2.0, 3.0]], &mut out).is_none());
        assert!(native
            .eval_into(&[&[1.0, 2.0, 3.0], &[4.0]], &mut out[..1])
            .is_none());
        assert!(native
            .eval_into(&[&[1.0, 2.0, 3.0], &[4.0]], &mut out)
            .is_some());
        assert_eq!(out, [3.0, 4.0]);
    }

    /// Clones share one compilation through the process-wide table, but an
    /// edited clone (as the mutation sweep makes) gets its own code.
    #[test]
    fn an_edited_clone_never_runs_the_originals_code() {
        let f = Evaluator::new(function(vec![Op::Arg(0, 0), Op::Sin(0)], vec![1], 1));
        let hot =
            |g: &Evaluator, x: f64| (0..=HOT_CALLS).map(|_| g.eval(&[&[x]])[0]).last().unwrap();
        assert_eq!(hot(&f, 0.3), libm::sin(0.3));
        let same = f.clone();
        assert_eq!(hot(&same, 0.3), libm::sin(0.3));
        let edited = Evaluator::new(Function {
            tape: vec![Op::Arg(0, 0), Op::Cos(0)],
            ..(*f).clone()
        });
        assert_eq!(hot(&edited, 0.3), libm::cos(0.3));
        assert_eq!(format!("{:?}", edited.cache), "NativeCache(compiled)");
    }

    #[test]
    fn a_hot_function_is_compiled_and_a_clone_starts_cold() {
        let f = Evaluator::new(function(vec![Op::Arg(0, 0), Op::Sin(0)], vec![1], 1));
        for _ in 0..=HOT_CALLS {
            assert_eq!(f.eval(&[&[0.5]])[0], libm::sin(0.5));
        }
        assert_eq!(format!("{:?}", f.cache), "NativeCache(compiled)");
        assert_eq!(format!("{:?}", f.clone().cache), "NativeCache(interpreted)");
    }

    /// An IR's functions are found by reference: its own are compiled once
    /// hot, a copy of one is interpreted (never another function's code).
    #[test]
    fn an_irs_functions_are_compiled_by_reference_and_copies_interpreted() {
        let text = include_str!("../../generated/ir/unicycle_ekf.json");
        let ir = ModelIr::from_json(text).unwrap();
        let code = IrCode::new(&ir);
        let twist = ir.twist();
        let copy = twist.clone();
        let (u, p) = ([0.5, 0.1], [0.0; 8]);
        let args: [&[f64]; 2] = [&u, &p[..ir.runtime_params().len()]];
        let (mut a, mut b) = ([0.0; 3], [0.0; 3]);
        for _ in 0..=HOT_CALLS {
            code.eval_into(&ir, twist, &args, &mut a, &mut Vec::new());
            code.eval_into(&ir, &copy, &args, &mut b, &mut Vec::new());
        }
        assert_eq!(a, b);
        let i = ir
            .functions()
            .iter()
            .position(|f| std::ptr::eq(f, twist))
            .unwrap();
        assert_eq!(format!("{:?}", code.caches[i]), "NativeCache(compiled)");
        assert!(code.cache(&ir, &copy).is_none());
    }
}

#[cfg(test)]
mod bundled {
    use super::*;
    use kinegen_model::ir::ModelIr;

    /// Every tape of every bundled model, compiled, gives the interpreter's
    /// outputs to the last bit on inputs across several scales (including the
    /// series side of every guard: zero rates).
    #[test]
    fn every_bundled_tape_compiles_to_the_interpreters_results() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../generated/ir");
        let mut checked = 0;
        for entry in std::fs::read_dir(dir).unwrap() {
            let text = std::fs::read_to_string(entry.unwrap().path()).unwrap();
            let ir = ModelIr::from_json(&text).unwrap();
            for f in ir.functions() {
                let native = Native::compile(f)
                    .unwrap_or_else(|| panic!("{}::{} does not compile", ir.name, f.name));
                for trial in 0..40u64 {
                    let values: Vec<Vec<f64>> = f
                        .args
                        .iter()
                        .enumerate()
                        .map(|(a, spec)| {
                            (0..spec.names.len())
                                .map(|i| {
                                    // a cheap deterministic spread; every 4th trial all zero
                                    let h = (trial * 131 + a as u64 * 31 + i as u64 * 7) % 97;
                                    if trial % 4 == 0 {
                                        0.0
                                    } else {
                                        0.05 + (h as f64 / 97.0 - 0.3) * (1 + trial % 3) as f64
                                    }
                                })
                                .collect()
                        })
                        .collect();
                    let args: Vec<&[f64]> = values.iter().map(Vec::as_slice).collect();
                    let n = f.rows * f.cols;
                    let (mut got, mut want) = (vec![0.0; n], vec![0.0; n]);
                    native.eval_into(&args, &mut got).unwrap();
                    f.interpret_into(&args, &mut want, &mut Vec::new());
                    for (k, (g, w)) in got.iter().zip(&want).enumerate() {
                        assert!(
                            g.to_bits() == w.to_bits() || (g.is_nan() && w.is_nan()),
                            "{}::{} output {k}: compiled {g:e}, interpreted {w:e}",
                            ir.name,
                            f.name
                        );
                    }
                }
                checked += 1;
            }
        }
        assert!(checked > 50, "only {checked} bundled functions found");
    }
}
