//! Rust emission: one `#![no_std]`-compatible module per model, built with quote
//! and formatted with prettyplease. Kernels take and return plain arrays, use libm
//! for transcendental functions, never allocate and never panic.
use kinegen_model::ir::{ArgKind, ArgSpec, Function, ModelIr, Op, StepForm};
use kinegen_model::schedule::{Group, Item};
use proc_macro2::{Literal, TokenStream};
use quote::{format_ident, quote};

/// A float literal without suffix: its type is the kernels' `Real` (f64, or
/// f32 with the generated crate's `f32` feature), inferred from the context.
fn lit(c: f64) -> TokenStream {
    let l = Literal::f64_unsuffixed(c.abs());
    if c.is_sign_negative() {
        quote!((-#l))
    } else {
        quote!(#l)
    }
}

fn arg_type(a: &ArgSpec) -> TokenStream {
    match a.kind() {
        ArgKind::Scalar => quote!(crate::Real),
        ArgKind::Vector(len) => quote!(&[crate::Real; #len]),
    }
}

/// Tape length above which a kernel is emitted with an array of temporaries.
const BIG_KERNEL: usize = 1500;

/// A kernel's parameter list: each argument with its array type.
fn params(f: &Function) -> Vec<TokenStream> {
    f.args
        .iter()
        .map(|a| {
            let id = format_ident!("{}", a.ident());
            let ty = arg_type(a);
            quote!(#id: #ty)
        })
        .collect()
}

fn emit_function(f: &Function) -> TokenStream {
    let name = format_ident!("{}", f.name);
    let params = params(f);
    // Small kernels bind one `let` per op (readable, and what the optimiser likes
    // best). Very large ones (the parameter Jacobians of a least-squares model) write
    // into one local array instead: thousands of nested `let` scopes overflow rustc's
    // debug-info generation (SIGSEGV in LLVM's DWARF writer). Constant indices into a
    // fixed-size array are checked at compile time, so this adds no panic path.
    let big = f.tape.len() > BIG_KERNEL;
    let t = |i: u32| -> TokenStream {
        if big {
            let i = i as usize;
            quote!(t[#i])
        } else {
            let id = format_ident!("t{}", i);
            quote!(#id)
        }
    };
    let bind = |i: usize, e: TokenStream| -> TokenStream {
        if big {
            quote!(t[#i] = #e;)
        } else {
            let id = format_ident!("t{}", i);
            quote!(let #id: crate::Real = #e;)
        }
    };
    // one pseudo-inverse per distinct matrix; its entries are then read from it
    let mut pinvs: Vec<[u32; 6]> = Vec::new();
    let mut stmts = Vec::new();
    if big {
        let n = f.tape.len();
        stmts.push(quote!(let mut t: [crate::Real; #n] = [0.0; #n];));
    }
    // one statement per slot, in tape order; a NearZero slot's statement is
    // assembled afterwards (its branches hold statements of other slots)
    let mut slot_stmts: Vec<Vec<TokenStream>> = vec![Vec::new(); f.tape.len()];
    for (i, op) in f.tape.iter().enumerate() {
        let stmts = &mut slot_stmts[i];
        if let Op::PinvSym3 { m, i: r, j: c } = *op {
            let k = pinvs.iter().position(|x| *x == m).unwrap_or_else(|| {
                pinvs.push(m);
                let id = format_ident!("pinv{}", pinvs.len() - 1);
                let args = m.map(t);
                stmts.push(
                    quote!(let #id: [crate::Real; 6] = crate::linalg::pinv_sym3([#(#args),*]);),
                );
                pinvs.len() - 1
            });
            let id = format_ident!("pinv{}", k);
            let idx = kinegen_model::linalg::packed_index(r as usize, c as usize);
            stmts.push(bind(i, quote!(#id[#idx])));
            continue;
        }
        let expr = match *op {
            Op::NearZero { .. } => continue, // see below
            _ => op_expr(f, op, &t),
        };
        stmts.push(bind(i, expr));
    }
    // Each guard evaluates only the side its condition selects, and guards on one
    // condition share one `if` (kinegen_model::schedule).
    let (items, groups) = kinegen_model::schedule::schedule(&f.tape, &f.outputs);
    stmts.extend(emit_items(&items, &groups, f, &mut slot_stmts, &t, &bind));
    let (ret_ty, ret) = if f.is_matrix() {
        let (r, c) = (f.rows, f.cols);
        let rows = f.outputs.chunks(c).map(|row| {
            let row = row.iter().map(|&o| t(o));
            quote!([#(#row),*])
        });
        (quote!([[crate::Real; #c]; #r]), quote!([#(#rows),*]))
    } else {
        let r = f.rows;
        let outs = f.outputs.iter().map(|&o| t(o));
        (quote!([crate::Real; #r]), quote!([#(#outs),*]))
    };
    let doc = function_doc(f);
    quote! {
        #[doc = #doc]
        #[inline]
        pub fn #name(#(#params),*) -> #ret_ty {
            #(#stmts)*
            #ret
        }
    }
}

/// The expression computing one tape slot (not a pseudo-inverse entry or a
/// series switch, which the caller assembles), its operands read through `t`.
fn op_expr(f: &Function, op: &Op, t: &dyn Fn(u32) -> TokenStream) -> TokenStream {
    match *op {
        Op::Const(c) => lit(c),
        Op::Arg(a, k) => {
            let spec = &f.args[a as usize];
            let id = format_ident!("{}", spec.ident());
            match spec.kind() {
                ArgKind::Scalar => quote!(#id),
                ArgKind::Vector(_) => {
                    let k = k as usize;
                    quote!(#id[#k])
                }
            }
        }
        Op::Add(a, b) => {
            let (a, b) = (t(a), t(b));
            quote!(#a + #b)
        }
        Op::Sub(a, b) => {
            let (a, b) = (t(a), t(b));
            quote!(#a - #b)
        }
        Op::Mul(a, b) => {
            let (a, b) = (t(a), t(b));
            quote!(#a * #b)
        }
        Op::Div(a, b) => {
            let (a, b) = (t(a), t(b));
            quote!(#a / #b)
        }
        Op::Neg(a) => {
            let a = t(a);
            quote!(-#a)
        }
        // small integer powers as products: cheaper than pow and exact
        // (up to the cube the plain product is the same chain, bit for bit)
        Op::PowI(a, n) if (1..=3).contains(&n) => {
            let a = t(a);
            (1..n).fold(quote!(#a), |e, _| quote!(#e * #a))
        }
        // larger ones as the multiplication chain of binary exponentiation
        // (the order f64::powi and the evaluator's JIT use), not a pow call
        Op::PowI(a, n) if n != 0 && n.unsigned_abs() <= 64 => {
            let a = t(a);
            let chain = powi_chain(quote!(#a), n.unsigned_abs());
            if n < 0 {
                quote!(1.0 / #chain)
            } else {
                chain
            }
        }
        Op::PowI(a, n) => {
            let a = t(a);
            let n = lit(n as f64);
            quote!(crate::math::pow(#a, #n))
        }
        Op::Pow(a, b) => {
            let (a, b) = (t(a), t(b));
            quote!(crate::math::pow(#a, #b))
        }
        Op::Sqrt(a) => {
            let a = t(a);
            quote!(crate::math::sqrt(#a))
        }
        Op::Sin(a) => {
            let a = t(a);
            quote!(crate::math::sin(#a))
        }
        Op::Cos(a) => {
            let a = t(a);
            quote!(crate::math::cos(#a))
        }
        Op::Tan(a) => {
            let a = t(a);
            quote!(crate::math::tan(#a))
        }
        Op::Atan(a) => {
            let a = t(a);
            quote!(crate::math::atan(#a))
        }
        Op::Atan2(a, b) => {
            let (a, b) = (t(a), t(b));
            quote!(crate::math::atan2(#a, #b))
        }
        Op::Exp(a) => {
            let a = t(a);
            quote!(crate::math::exp(#a))
        }
        Op::Ln(a) => {
            let a = t(a);
            quote!(crate::math::log(#a))
        }
        Op::Abs(a) => {
            let a = t(a);
            quote!(crate::math::fabs(#a))
        }
        Op::Sign(a) => {
            let a = t(a);
            quote!(crate::math::sign(#a))
        }
        Op::NearZero { .. } | Op::PinvSym3 { .. } => {
            unreachable!("pseudo-inverse entries and series switches are assembled by the caller")
        }
    }
}

/// A kernel's doc comment: what it computes, its arguments, its outputs and
/// its operation counts.
fn function_doc(f: &Function) -> String {
    let mut doc = vec![f.doc.clone(), String::new()];
    for a in &f.args {
        doc.push(format!("* `{}`: [{}]", a.ident(), a.names.join(", ")));
    }
    if f.is_matrix() {
        doc.push(format!(
            "* returns rows [{}], columns [{}]",
            f.row_names.join(", "),
            f.col_names.join(", ")
        ));
    } else {
        doc.push(format!("* returns [{}]", f.row_names.join(", ")));
    }
    doc.push(format!(
        "\n{} arithmetic operations ({} before common-subexpression elimination).",
        f.ops_tape(),
        f.ops_tree
    ));
    doc.join("\n")
}

/// The statements of `items` (see [`kinegen_model::schedule`]): a guard group binds its
/// members from one array-valued `if` whose sides emit their own statements first.
fn emit_items(
    items: &[Item],
    groups: &[Group],
    f: &Function,
    slot_stmts: &mut [Vec<TokenStream>],
    t: &dyn Fn(u32) -> TokenStream,
    bind: &dyn Fn(usize, TokenStream) -> TokenStream,
) -> Vec<TokenStream> {
    let mut out = Vec::new();
    let pairs = sincos_pairs(items, &f.tape);
    for item in items {
        match item {
            Item::Slot(s) => match pairs.iter().find(|p| p.contains(s)) {
                // the first of a sine and cosine pair computes both
                Some(&[sin, cos]) if *s == sin.min(cos) => {
                    let Op::Sin(a) = f.tape[sin] else {
                        unreachable!("a pair starts with a sine")
                    };
                    let (a, id) = (t(a), format_ident!("sc{}", s));
                    out.push(quote!(let #id = crate::math::sincos(#a);));
                    out.push(bind(sin, quote!(#id.0)));
                    out.push(bind(cos, quote!(#id.1)));
                    slot_stmts[sin].clear();
                    slot_stmts[cos].clear();
                }
                Some(_) => {}
                None => out.append(&mut slot_stmts[*s]),
            },
            Item::Guard { group, near, far } => {
                let g = &groups[*group];
                let sides = |near_side: bool| -> Vec<TokenStream> {
                    g.members
                        .iter()
                        .map(|&m| match f.tape[m] {
                            Op::NearZero { near, far, .. } => t(if near_side { near } else { far }),
                            _ => unreachable!("a guard group holds NearZero slots"),
                        })
                        .collect()
                };
                let (near_vals, far_vals) = (sides(true), sides(false));
                let near_stmts = emit_items(near, groups, f, slot_stmts, t, bind);
                let far_stmts = emit_items(far, groups, f, slot_stmts, t, bind);
                let (x, eps, k) = (t(g.x), lit(g.eps), g.members.len());
                let id = format_ident!("g{}", group);
                out.push(quote! {
                    let #id: [crate::Real; #k] = if crate::math::fabs(#x) < crate::math::series_switch(#eps) {
                        #(#near_stmts)* [#(#near_vals),*]
                    } else {
                        #(#far_stmts)* [#(#far_vals),*]
                    };
                });
                for (j, &m) in g.members.iter().enumerate() {
                    out.push(bind(m, quote!(#id[#j])));
                }
            }
        }
    }
    out
}

/// [sine slot, cosine slot] of each operand whose sine and cosine are both
/// computed directly in `items` (one block): libm's `sincos` shares their
/// argument reduction. A pair split across a branch is left as two calls.
fn sincos_pairs(items: &[Item], tape: &[Op]) -> Vec<[usize; 2]> {
    let slot = |want_sin: bool, a: u32| {
        items.iter().find_map(|it| match (it, want_sin) {
            (Item::Slot(s), true) if tape[*s] == Op::Sin(a) => Some(*s),
            (Item::Slot(s), false) if tape[*s] == Op::Cos(a) => Some(*s),
            _ => None,
        })
    };
    items
        .iter()
        .filter_map(|it| match it {
            Item::Slot(s) => match tape[*s] {
                Op::Sin(a) => Some([*s, slot(false, a)?]),
                _ => None,
            },
            _ => None,
        })
        .collect()
}

/// `x^n` (n >= 1) as one block of multiplications: the factors x, x^2, x^4...
/// by repeated squaring, multiplied in from the lowest bit of n up.
fn powi_chain(x: TokenStream, n: u32) -> TokenStream {
    let mut stmts = vec![quote!(let s0 = #x;)];
    let mut result: Option<TokenStream> = None;
    let bits = 32 - n.leading_zeros();
    for k in 0..bits {
        let s = format_ident!("s{}", k);
        if n & (1 << k) != 0 {
            result = Some(match result {
                None => quote!(#s),
                Some(r) => {
                    let r_id = format_ident!("r{}", k);
                    stmts.push(quote!(let #r_id = #r * #s;));
                    quote!(#r_id)
                }
            });
        }
        if k + 1 < bits {
            let next = format_ident!("s{}", k + 1);
            stmts.push(quote!(let #next = #s * #s;));
        }
    }
    let r = result.expect("n >= 1");
    quote!({ #(#stmts)* #r })
}

/// Fused kernels that share work, as SymForce's `with_jacobians` functions do:
/// (name, doc, parts). An EKF predict takes the pose with its Jacobians wrt the
/// state and the noise; a calibration step the pose with its Jacobians wrt the
/// state and the parameters; an update each observation with its Jacobians.
fn fused_kernels(ir: &ModelIr) -> Vec<(String, String, Vec<&Function>)> {
    let exact = ir.step(StepForm::Exact);
    let mut want: Vec<(String, String, Vec<Option<&Function>>)> = vec![
        (
            "step_exact_linearized".into(),
            "The exact step with its Jacobians wrt the state and the process noise, from one shared computation: an EKF's prediction (seed 001 eq. 2-3).".into(),
            vec![Some(exact.value), Some(exact.jac_x), exact.jac_w],
        ),
        (
            "step_exact_with_jac_p".into(),
            "The exact step with its Jacobians wrt the state and the parameters, from one shared computation: one step of calibration's forward sensitivities.".into(),
            vec![Some(exact.value), Some(exact.jac_x), exact.jac_p],
        ),
    ];
    for i in 0..ir.observations().len() {
        let o = ir.observation_kernels_at(i);
        want.push((
            format!("obs_{}_linearized", o.decl.name),
            format!("Observation `{}` with its Jacobians wrt the state and the parameters, from one shared computation: an EKF's update.", o.decl.name),
            vec![Some(o.value), Some(o.jac_x), o.jac_p],
        ));
    }
    want.into_iter()
        .filter_map(|(name, doc, parts)| {
            let parts: Option<Vec<&Function>> = parts.into_iter().collect();
            parts.map(|p| (name, doc, p))
        })
        .collect()
}

/// A fused kernel: the flat function (every part's outputs one after another)
/// and a wrapper returning each part in its own shape.
fn emit_fused(name: &str, doc: &str, parts: &[&Function]) -> TokenStream {
    let flat_name = format!("{name}_flat");
    let mut flat = kinegen_model::fuse::fuse(&flat_name, parts).expect("parts of one model fuse");
    flat.doc = format!(
        "{doc} Outputs one after another: {} (row-major); see `{name}`.",
        parts
            .iter()
            .map(|p| p.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    );
    let flat_fn = emit_function(&flat);
    let id = format_ident!("{}", name);
    let flat_id = format_ident!("{}", flat_name);
    let params = params(&flat);
    let vars = flat.args.iter().map(|a| format_ident!("{}", a.ident()));
    let mut at = 0usize;
    let (mut tys, mut vals) = (Vec::new(), Vec::new());
    for p in parts {
        let (r, c) = (p.rows, p.cols);
        if p.is_matrix() {
            let rows = (0..r).map(|i| {
                let row = (0..c).map(|j| at + i * c + j);
                quote!([#(o[#row]),*])
            });
            tys.push(quote!([[crate::Real; #c]; #r]));
            vals.push(quote!([#(#rows),*]));
        } else {
            let row = (0..r).map(|i| at + i);
            tys.push(quote!([crate::Real; #r]));
            vals.push(quote!([#(o[#row]),*]));
        }
        at += r * c;
    }
    let doc = format!(
        "{doc}\n\nReturns ({}), each exactly as that kernel alone returns it.",
        parts
            .iter()
            .map(|p| format!("`{}`", p.name))
            .collect::<Vec<_>>()
            .join(", ")
    );
    quote! {
        #flat_fn
        #[doc = #doc]
        #[inline]
        pub fn #id(#(#params),*) -> (#(#tys),*) {
            let o = #flat_id(#(#vars),*);
            (#(#vals),*)
        }
    }
}

/// A parameter's name as a struct field: a Rust keyword becomes a raw
/// identifier (`r#type`), and the four that cannot be raw get a trailing `_`.
fn field_ident(name: &str) -> proc_macro2::Ident {
    match name {
        "self" | "Self" | "super" | "crate" => format_ident!("{}_", name),
        _ if syn::parse_str::<syn::Ident>(name).is_err() => {
            proc_macro2::Ident::new_raw(name, proc_macro2::Span::call_site())
        }
        _ => format_ident!("{}", name),
    }
}

/// The `call` dispatcher's arm for kernel `f`: check the slices' lengths,
/// convert them to the kernel's argument types, call it, copy its output.
fn dispatch_arm(f: &Function) -> TokenStream {
    let name = &f.name;
    let id = format_ident!("{}", f.name);
    let conv = f.args.iter().enumerate().map(|(i, a)| {
        let v = format_ident!("a{}", i);
        match a.kind() {
            ArgKind::Scalar => quote!(let #v: crate::Real = match args[#i] { [v] => *v, _ => return false };),
            ArgKind::Vector(n) => quote!(let #v: &[crate::Real; #n] = match <&[crate::Real; #n]>::try_from(args[#i]) { Ok(v) => v, Err(_) => return false };),
        }
    });
    let vars = (0..f.args.len()).map(|i| format_ident!("a{}", i));
    let nargs = f.args.len();
    let n_out = f.rows * f.cols;
    let flatten = if f.is_matrix() {
        quote!(let r = r.as_flattened();)
    } else {
        quote!(let r = &r[..];)
    };
    quote! {
        #name => {
            if args.len() != #nargs || out.len() != #n_out { return false; }
            #(#conv)*
            let r = #id(#(#vars),*);
            #flatten
            out.copy_from_slice(r);
            true
        }
    }
}

/// The doc comment of a parameter's field: its name, unit and doc.
fn field_doc(p: &kinegen_model::decl::Param) -> String {
    let unit = if p.unit.is_empty() {
        String::new()
    } else {
        format!(" ({})", p.unit)
    };
    let doc = if p.doc.is_empty() {
        String::new()
    } else {
        format!(": {}", p.doc)
    };
    format!(" `{}`{unit}{doc}", p.name)
}

/// The source of one model's module.
pub fn emit_module(ir: &ModelIr, spec_path: &str) -> String {
    let header = format!(
        "{}\n\nGenerated by `kinegen generate` from `{spec_path}` (spec fingerprint {}). Do not edit: change the spec and regenerate.{}",
        ir.doc,
        ir.spec_fingerprint,
        if ir.seed.is_empty() { String::new() } else { format!("\n\nReference: seed {}.", ir.seed) }
    );
    let fp = &ir.spec_fingerprint;
    let pnames: Vec<&str> = ir
        .runtime_params()
        .iter()
        .map(|p| p.name.as_str())
        .collect();
    let pnom: Vec<TokenStream> = ir.runtime_params().iter().map(|p| lit(p.nominal)).collect();
    let np = pnames.len();
    let fields: Vec<proc_macro2::Ident> = pnames.iter().map(|n| field_ident(n)).collect();
    let field_docs: Vec<String> = ir.runtime_params().into_iter().map(field_doc).collect();
    let idx: Vec<usize> = (0..np).collect();
    let inames: Vec<&str> = ir.inputs.iter().map(|i| i.name.as_str()).collect();
    let icols: Vec<&str> = ir.inputs.iter().map(|i| i.column.as_str()).collect();
    let ni = inames.len();
    let fns = ir.functions().iter().map(emit_function);
    let fused = fused_kernels(ir);
    let fused = fused.iter().map(|(n, d, parts)| emit_fused(n, d, parts));
    let arms = ir.functions().iter().map(dispatch_arm);
    let file = quote! {
        #![doc = #header]
        // parameter fields keep the spec's names (`L`, as the papers write it)
        #![allow(clippy::all, unused_parens, unused_variables, clippy::excessive_precision, non_snake_case)]

        /// Fingerprint of the spec this module was generated from.
        pub const SPEC_FINGERPRINT: &str = #fp;
        /// Runtime parameters, in the order of the `p` argument.
        pub const PARAMS: [&str; #np] = [#(#pnames),*];
        /// Nominal values of [`PARAMS`].
        pub const PARAM_NOMINAL: [crate::Real; #np] = [#(#pnom),*];

        /// The runtime parameters by name; [`Params::to_array`] gives the `p`
        /// argument of every kernel.
        #[derive(Debug, Clone, Copy, PartialEq)]
        pub struct Params {
            #(#[doc = #field_docs] pub #fields: crate::Real,)*
        }

        impl Params {
            /// The spec's nominal values.
            pub const NOMINAL: Params = Params { #(#fields: PARAM_NOMINAL[#idx]),* };

            /// The `p` argument of the kernels, in the order of [`PARAMS`].
            pub const fn to_array(&self) -> [crate::Real; #np] {
                [#(self.#fields),*]
            }

            /// From a `p` array in the order of [`PARAMS`].
            pub const fn from_array(p: &[crate::Real; #np]) -> Params {
                Params { #(#fields: p[#idx]),* }
            }
        }
        /// Inputs, in the order of the `u` argument.
        pub const INPUTS: [&str; #ni] = [#(#inames),*];
        /// Log column feeding each input.
        pub const INPUT_COLUMNS: [&str; #ni] = [#(#icols),*];

        #(#fns)*

        #(#fused)*

        /// Call a kernel by name with slices (arguments in declaration order, output
        /// row-major), for verification tools. Returns false for an unknown name or
        /// wrong lengths. Behind the `dispatch` feature: firmware calls the
        /// kernels themselves and need not carry every kernel and its name.
        #[cfg(feature = "dispatch")]
        pub fn call(name: &str, args: &[&[crate::Real]], out: &mut [crate::Real]) -> bool {
            match name {
                #(#arms)*
                _ => false,
            }
        }
    };
    let parsed: syn::File = syn::parse2(file).expect("emitted module parses");
    prettyplease::unparse(&parsed)
}

/// The generated crate's `linalg.rs`: a verbatim copy of the routine the IR
/// evaluator uses, so compiled and interpreted kernels share one implementation.
pub fn emit_linalg() -> String {
    // The same text, for the crate's `Real` and its `math` functions: the local
    // tolerance function gives way to the one that knows the float type.
    let source = include_str!("../../model/src/linalg.rs");
    let local = source
        .find("const fn tolerance(")
        .and_then(|a| source[a..].find("\n}\n").map(|b| (a, a + b + 3)))
        .expect("model/src/linalg.rs defines `tolerance`");
    let text = format!(
        "{}use crate::math::tolerance;\n{}",
        &source[..local.0],
        &source[local.1..]
    );
    let text = text.replace("libm::", "crate::math::");
    let text = f64_as_real(&text);
    format!(
        "// Generated by `kinegen generate`: a copy of model/src/linalg.rs for the crate's Real type. Do not edit.\n{text}"
    )
}

/// Every `f64` type of a Rust text as `crate::Real` (whole words only).
fn f64_as_real(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(i) = rest.find("f64") {
        let before = rest[..i].chars().last();
        let after = rest[i + 3..].chars().next();
        let word = |c: Option<char>| c.is_some_and(|c| c.is_alphanumeric() || c == '_');
        out.push_str(&rest[..i]);
        out.push_str(if word(before) || word(after) {
            "f64"
        } else {
            "crate::Real"
        });
        rest = &rest[i + 3..];
    }
    out.push_str(rest);
    out
}

/// The generated crate's `math.rs`: the float functions for its `Real`.
pub fn emit_math() -> String {
    include_str!("math.rs.in").to_string()
}

/// The generated crate's lib.rs listing every model module.
pub fn emit_lib(models: &[String]) -> String {
    let mods = models.iter().map(|m| {
        let id = format_ident!("{}", m);
        // the emitter's layout is the reference (`generate --check`), not rustfmt's
        quote!(#[rustfmt::skip] pub mod #id;)
    });
    let names = models.iter();
    let idents = models.iter().map(|m| format_ident!("{}", m));
    let calls = models.iter().map(|m| {
        let id = format_ident!("{}", m);
        quote!(#m => #id::call(function, args, out),)
    });
    let fps = models.iter().map(|m| {
        let id = format_ident!("{}", m);
        quote!(#m => Some(#id::SPEC_FINGERPRINT),)
    });
    let file = quote! {
        #![doc = "Kinematic and observation kernels generated by kinegen from the specs in `spec/`.\n\nOne module per model. Every function takes and returns plain arrays of `Real` (`f64`; `f32` with the `f32` feature), does not allocate and does not panic; the crate is `no_std` (libm supplies the transcendental functions) so the kernels can run on a robot's microcontroller. Enable the `nalgebra` feature for conversions to nalgebra types, and on a computer the `std` feature: std's (the C library's) exp and pow, faster than libm's; atan2 and atan are the crate's own, faster than both (see `math`).\n\nGenerated by `kinegen generate`; do not edit."]
        #![cfg_attr(not(feature = "std"), no_std)]

        /// The kernels' float type: `f64`, or `f32` with the `f32` feature (a
        /// microcontroller with a single-precision FPU).
        #[cfg(not(feature = "f32"))]
        pub type Real = f64;
        /// The kernels' float type: `f32` (the `f32` feature).
        #[cfg(feature = "f32")]
        pub type Real = f32;

        #[rustfmt::skip]
        pub mod linalg;
        #[rustfmt::skip]
        pub mod math;
        #(#mods)*

        /// The models in this crate.
        pub const MODELS: &[&str] = &[#(#names),*];

        /// Invoke the macro `$m` with the module name of every model of this
        /// crate, `$m!(diff_drive, tricycle, ...)`: code written once for all
        /// models (tests, probes) takes in a new model by itself.
        #[macro_export]
        #[rustfmt::skip]
        macro_rules! for_each_model {
            ($m:ident) => { $m!(#(#idents),*) };
        }

        /// The fingerprint of the spec a model was generated from.
        pub fn spec_fingerprint(model: &str) -> Option<&'static str> {
            match model {
                #(#fps)*
                _ => None,
            }
        }

        /// Call `model::function` by name (see each module's `call`; `dispatch`
        /// feature).
        #[cfg(feature = "dispatch")]
        pub fn call(model: &str, function: &str, args: &[&[Real]], out: &mut [Real]) -> bool {
            match model {
                #(#calls)*
                _ => false,
            }
        }

        /// Conversions between the kernels' plain arrays and nalgebra types.
        #[cfg(feature = "nalgebra")]
        pub mod na {
            use super::Real;

            /// A kernel's vector output as a nalgebra vector.
            pub fn vector<const N: usize>(a: [Real; N]) -> nalgebra::SVector<Real, N> {
                nalgebra::SVector::from(a)
            }
            /// A kernel's row-major matrix output as a nalgebra matrix.
            pub fn matrix<const R: usize, const C: usize>(a: [[Real; C]; R]) -> nalgebra::SMatrix<Real, R, C> {
                nalgebra::SMatrix::from_fn(|r, c| a[r][c])
            }
            /// A nalgebra vector as a kernel argument.
            pub fn array<const N: usize>(v: &nalgebra::SVector<Real, N>) -> [Real; N] {
                core::array::from_fn(|i| v[i])
            }
        }
    };
    let parsed: syn::File = syn::parse2(file).expect("lib parses");
    prettyplease::unparse(&parsed)
}

/// What a code generator provides for the crate `kinegen generate` writes:
/// one module per model and the crate's shared files. The derivation hands
/// every backend the same [`ModelIr`]; Rust is the one backend today.
pub trait Backend {
    /// The model's module: (path relative to the crate, source).
    fn module(&self, ir: &ModelIr, spec_path: &str) -> (std::path::PathBuf, String);
    /// The crate's files that are not one model's (path relative to the crate, source).
    fn shared(&self, models: &[String]) -> Vec<(std::path::PathBuf, String)>;
}

/// `no_std` Rust over libm (the `kinegen-generated` crate).
pub struct RustBackend;

impl Backend for RustBackend {
    fn module(&self, ir: &ModelIr, spec_path: &str) -> (std::path::PathBuf, String) {
        (
            std::path::Path::new("src").join(format!("{}.rs", ir.name)),
            emit_module(ir, spec_path),
        )
    }

    fn shared(&self, models: &[String]) -> Vec<(std::path::PathBuf, String)> {
        let src = std::path::Path::new("src");
        vec![
            (src.join("lib.rs"), emit_lib(models)),
            (src.join("linalg.rs"), emit_linalg()),
            (src.join("math.rs"), emit_math()),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// x^5 = x * (x^2)^2, multiplied in from the lowest bit, as f64::powi and
    /// the evaluator's JIT do it (the same bits).
    #[test]
    fn integer_powers_are_multiplication_chains() {
        let chain = powi_chain(quote!(x), 5).to_string();
        assert_eq!(
            chain,
            quote!({
                let s0 = x;
                let s1 = s0 * s0;
                let s2 = s1 * s1;
                let r2 = s0 * s2;
                r2
            })
            .to_string()
        );
        let x = 1.1f64;
        let s2 = (x * x) * (x * x);
        assert_eq!((x * s2).to_bits(), x.powi(5).to_bits());
    }

    /// Parameter names that are Rust keywords still make struct fields.
    #[test]
    fn keyword_parameters_become_valid_fields() {
        for (name, want) in [
            ("b", "b"),
            ("type", "r#type"),
            ("fn", "r#fn"),
            ("self", "self_"),
            ("crate", "crate_"),
        ] {
            let f = field_ident(name);
            assert_eq!(f.to_string(), want);
            let item = quote!(pub struct P { pub #f: f64 });
            syn::parse2::<syn::ItemStruct>(item).unwrap_or_else(|e| panic!("{name}: {e}"));
        }
    }
}
