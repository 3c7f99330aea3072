//! Bridge between spec expressions and symbolica atoms.
//!
//! Symbolica differentiates sin, cos, exp, log and powers itself. For tan, atan,
//! atan2 and abs it would leave `der(...)` placeholders, so we declare our own
//! function symbols with explicit derivative rules ([`Funcs`]). After every
//! derivation [`check_no_placeholder`] makes a leftover placeholder a hard error.
use kinegen_model::expr::{BinOp, Expr, ExprKind};
use std::collections::HashMap;
use symbolica::atom::{Atom, AtomCore, AtomView, Symbol};
use symbolica::{function, symbol};

/// Our function symbols with their derivative rules.
#[derive(Clone, Copy)]
pub struct Funcs {
    pub tan: Symbol,
    pub atan: Symbol,
    pub atan2: Symbol,
    pub abs: Symbol,
    pub sign: Symbol,
    /// `kg_near(s, series, closed)`: the series branch of a removable singularity
    /// at s = 0 (lowered to `Op::NearZero`; never differentiated).
    pub near: Symbol,
    /// `kg_pinv(i, j, m00, m01, m02, m11, m12, m22)`: entry (i, j), i <= j, of the
    /// pseudo-inverse P of the symmetric matrix M (lowered to `Op::PinvSym3`).
    /// Derivative: dP = -P dM P, so d P_ij / d m_ab = -(P_ia P_bj + P_ib P_aj)
    /// for a != b and -P_ia P_aj for a = b; again entries of P.
    pub pinv: Symbol,
    /// `kg_lsq(k, n, S (n x 3, row-major), q (n))`: component k of the least-squares
    /// solution z = (S^T S)^+ S^T q (seed 000 eq. 9-10), lowered through
    /// `kg_pinv`. Its own derivative rule, from dz = P (dS^T (q - S z) - S^T dS z)
    /// and dz = P S^T dq, is a few products per argument; differentiating the
    /// expanded P S^T q instead goes through dP = -P dM P for every entry of M,
    /// which made seed 000's parameter Jacobian 2.4x longer than wrenfold's.
    pub lsq: Symbol,
}

/// (a, b) of the packed argument k (after the two index arguments) of `kg_pinv`.
const PACKED: [(usize, usize); 6] = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];

/// `kg_pinv(i, j, m...)` with the indices put in order (P is symmetric).
pub fn pinv_entry(i: usize, j: usize, m: &[Atom]) -> Atom {
    let (a, b) = if i <= j { (i, j) } else { (j, i) };
    let mut fb = symbolica::atom::FunctionBuilder::new(symbol!("kg_pinv"))
        .add_arg(Atom::num(a as i64))
        .add_arg(Atom::num(b as i64));
    for x in m {
        fb = fb.add_arg(x);
    }
    fb.finish()
}

/// The normal-equation matrix M = S^T S (packed upper triangle) and S^T q of a
/// least-squares problem with rows `s` and right-hand side `q`.
pub fn normal_equations(s: &[[Atom; 3]], q: &[Atom]) -> ([Atom; 6], [Atom; 3]) {
    let m = PACKED.map(|(a, b)| {
        s.iter()
            .fold(Atom::num(0), |acc, row| acc + &row[a] * &row[b])
    });
    let stq = [0, 1, 2].map(|a| {
        s.iter()
            .zip(q)
            .fold(Atom::num(0), |acc, (row, qr)| acc + &row[a] * qr)
    });
    (m, stq)
}

/// `kg_lsq(k, ...)`: component k of the least-squares solution of `s` z = `q`.
pub fn lsq_entry(k: usize, s: &[[Atom; 3]], q: &[Atom]) -> Atom {
    let mut fb = symbolica::atom::FunctionBuilder::new(symbol!("kg_lsq"))
        .add_arg(Atom::num(k as i64))
        .add_arg(Atom::num(s.len() as i64));
    for x in s.iter().flatten().chain(q) {
        fb = fb.add_arg(x);
    }
    fb.finish()
}

/// The (k, S, q) of a `kg_lsq` call's arguments (None if malformed).
pub fn lsq_parts(args: &[Atom]) -> Option<(usize, Vec<[Atom; 3]>, Vec<Atom>)> {
    let num = |a: &Atom| as_f64(a.as_view()).map(|v| v as usize);
    let (k, n) = (num(args.first()?)?, num(args.get(1)?)?);
    if args.len() != 2 + 4 * n || k > 2 {
        return None;
    }
    let s = (0..n)
        .map(|r| [0, 1, 2].map(|a| args[2 + 3 * r + a].clone()))
        .collect();
    Some((k, s, args[2 + 3 * n..].to_vec()))
}

/// z_k = sum_j P_kj (S^T q)_j with the pseudo-inverse as `kg_pinv` entries: what
/// `kg_lsq(k, ...)` stands for.
pub fn lsq_expanded(k: usize, s: &[[Atom; 3]], q: &[Atom]) -> Atom {
    let (m, stq) = normal_equations(s, q);
    (0..3).fold(Atom::num(0), |acc, j| acc + pinv_entry(k, j, &m) * &stq[j])
}

impl Funcs {
    /// The process-wide function symbols (symbolica symbols can be defined once).
    pub fn get() -> Funcs {
        static FUNCS: std::sync::OnceLock<Funcs> = std::sync::OnceLock::new();
        *FUNCS.get_or_init(Funcs::define)
    }

    fn define() -> Funcs {
        let tan = symbol!(
            "kg_tan",
            der = |x, i, out| {
                // d tan(a)/da = 1 + tan(a)^2
                if let (0, AtomView::Fun(f)) = (i, x) {
                    let a = f.iter().next().unwrap().to_owned();
                    let t = function!(symbol!("kg_tan"), a);
                    **out = Atom::num(1) + &t * &t;
                }
            }
        );
        let atan = symbol!(
            "kg_atan",
            der = |x, i, out| {
                // d atan(a)/da = 1 / (1 + a^2)
                if let (0, AtomView::Fun(f)) = (i, x) {
                    let a = f.iter().next().unwrap().to_owned();
                    **out = (Atom::num(1) + &a * &a).pow(Atom::num(-1));
                }
            }
        );
        let atan2 = symbol!(
            "kg_atan2",
            der = |x, i, out| {
                // atan2(y, x): d/dy = x/(x^2+y^2), d/dx = -y/(x^2+y^2)
                if let AtomView::Fun(f) = x {
                    let mut it = f.iter();
                    let (y, xx) = (it.next().unwrap().to_owned(), it.next().unwrap().to_owned());
                    let r2inv = (&xx * &xx + &y * &y).pow(Atom::num(-1));
                    **out = if i == 0 { &xx * &r2inv } else { -(&y * &r2inv) };
                }
            }
        );
        let abs = symbol!(
            "kg_abs",
            der = |x, i, out| {
                // d|a|/da = sign(a), 0 at the kink: a/|a| would make every
                // derivative through |a| NaN where a = 0 (a deadband's |u + d|
                // at a stopped robot's command 0 and nominal d = 0)
                if let (0, AtomView::Fun(f)) = (i, x) {
                    let a = f.iter().next().unwrap().to_owned();
                    **out = function!(symbol!("kg_sign"), a);
                }
            }
        );
        let sign = symbol!(
            "kg_sign",
            der = |_, _, out| {
                // piecewise constant: 0 away from 0, where its jump has no derivative
                **out = Atom::num(0);
            }
        );
        let near = symbol!("kg_near");
        let pinv = symbol!(
            "kg_pinv",
            der = |x, k, out| {
                let AtomView::Fun(f) = x else { return };
                let args: Vec<Atom> = f.iter().map(|a| a.to_owned()).collect();
                if k < 2 || args.len() != 8 {
                    **out = Atom::num(0);
                    return;
                }
                let idx = |a: &Atom| as_f64(a.as_view()).map(|v| v as usize).unwrap_or(0);
                let (i, j) = (idx(&args[0]), idx(&args[1]));
                let m = &args[2..];
                let (a, b) = PACKED[k - 2];
                let p = |r: usize, c: usize| pinv_entry(r, c, m);
                **out = if a == b {
                    -(p(i, a) * p(a, j))
                } else {
                    -(p(i, a) * p(b, j) + p(i, b) * p(a, j))
                };
            }
        );
        let lsq = symbol!(
            "kg_lsq",
            der = |x, i, out| {
                let AtomView::Fun(f) = x else { return };
                let args: Vec<Atom> = f.iter().map(|a| a.to_owned()).collect();
                let Some((k, s, q)) = lsq_parts(&args) else {
                    return;
                };
                let n = s.len();
                if i < 2 {
                    **out = Atom::num(0);
                    return;
                }
                let (m, _) = normal_equations(&s, &q);
                let p = |r: usize, c: usize| pinv_entry(r, c, &m);
                // (P S^T)_{k r} = sum_b P_kb S_rb
                let pst = |r: usize| (0..3).fold(Atom::num(0), |acc, b| acc + p(k, b) * &s[r][b]);
                **out = if i < 2 + 3 * n {
                    let (r, a) = ((i - 2) / 3, (i - 2) % 3);
                    let z = |c: usize| lsq_entry(c, &s, &q);
                    let res = (0..3).fold(q[r].clone(), |acc, b| acc - &s[r][b] * z(b));
                    p(k, a) * res - pst(r) * z(a)
                } else {
                    pst(i - 2 - 3 * n)
                };
            }
        );
        Funcs {
            tan,
            atan,
            atan2,
            abs,
            sign,
            near,
            pinv,
            lsq,
        }
    }
}

/// An error while building or converting symbolic expressions.
#[derive(Debug, Clone, thiserror::Error)]
#[error("{0}")]
pub struct SymbolicError(pub String);

/// Exact rational for a decimal literal such as `0.042` or `1e-3`, so the
/// derivation works with exact numbers; falls back to a float beyond i64.
pub fn number(text: &str) -> Atom {
    let lower = text.to_ascii_lowercase();
    let (mantissa, exp10) = match lower.split_once('e') {
        Some((m, e)) => (m.to_string(), e.parse::<i32>().unwrap_or(0)),
        None => (lower.clone(), 0),
    };
    let (int_part, frac_part) = mantissa.split_once('.').unwrap_or((&mantissa, ""));
    let digits = format!("{int_part}{frac_part}");
    let scale = exp10 - frac_part.len() as i32;
    if let Ok(n) = digits.trim_start_matches('0').parse::<i64>().or_else(|_| {
        if digits.chars().all(|c| c == '0') {
            Ok(0)
        } else {
            Err(())
        }
    }) {
        if scale.unsigned_abs() <= 18 {
            let p = 10i64.pow(scale.unsigned_abs());
            return if scale >= 0 {
                n.checked_mul(p)
                    .map(Atom::num)
                    .unwrap_or_else(|| Atom::num(text.parse::<f64>().unwrap()))
            } else {
                Atom::num((n, p))
            };
        }
    }
    Atom::num(text.parse::<f64>().unwrap_or(f64::NAN))
}

/// Exact rational of an f64 (via its shortest decimal representation).
pub fn number_f64(v: f64) -> Atom {
    let s = format!("{v:e}");
    let neg = s.starts_with('-');
    let a = number(s.trim_start_matches('-'));
    if neg {
        -a
    } else {
        a
    }
}

/// Convert a spec expression (definitions already expanded) to an atom.
pub fn to_atom(e: &Expr, vars: &HashMap<String, Atom>, fx: &Funcs) -> Result<Atom, SymbolicError> {
    Ok(match &e.kind {
        ExprKind::Num(n) => number(n),
        ExprKind::Var(v) if v == "pi" => Atom::var(Symbol::PI),
        ExprKind::Var(v) => vars
            .get(v)
            .cloned()
            .ok_or_else(|| SymbolicError(format!("unbound symbol `{v}`")))?,
        ExprKind::Neg(a) => -to_atom(a, vars, fx)?,
        ExprKind::Bin(op, a, b) => {
            let (a, b) = (to_atom(a, vars, fx)?, to_atom(b, vars, fx)?);
            match op {
                BinOp::Add => a + b,
                BinOp::Sub => a - b,
                BinOp::Mul => a * b,
                BinOp::Div => a / b,
                BinOp::Pow => a.pow(b),
            }
        }
        ExprKind::Call(f, args) => {
            let a: Vec<Atom> = args
                .iter()
                .map(|x| to_atom(x, vars, fx))
                .collect::<Result<_, _>>()?;
            match f.as_str() {
                "sin" => a[0].sin(),
                "cos" => a[0].cos(),
                "exp" => a[0].exp(),
                "ln" => a[0].log(),
                "sqrt" => a[0].pow(Atom::num((1, 2))),
                "tan" => function!(fx.tan, a[0]),
                "atan" => function!(fx.atan, a[0]),
                "atan2" => function!(fx.atan2, a[0], a[1]),
                "abs" => function!(fx.abs, a[0]),
                "sign" => function!(fx.sign, a[0]),
                other => {
                    return Err(SymbolicError(format!(
                        "function `{other}` has no symbolic form"
                    )))
                }
            }
        }
    })
}

/// Fail if symbolica left a derivative placeholder (a function it cannot differentiate).
pub fn check_no_placeholder(a: &Atom, what: &str) -> Result<(), SymbolicError> {
    let s = a.to_string();
    if a.contains_symbol(Symbol::DERIVATIVE) || s.contains("der(") {
        return Err(SymbolicError(format!(
            "{what}: symbolica left a derivative placeholder in `{s}`"
        )));
    }
    Ok(())
}

/// f64 value of a numeric atom, if it is one.
pub fn as_f64(a: AtomView) -> Option<f64> {
    use symbolica::coefficient::CoefficientView;
    let AtomView::Num(n) = a else { return None };
    match n.get_coeff_view() {
        CoefficientView::Natural(nr, dr, 0, _) => Some(nr as f64 / dr as f64),
        CoefficientView::Large(r, i) if i.to_rat().is_zero() => Some(r.to_rat().to_f64()),
        CoefficientView::Float(r, i) if i.is_zero() => {
            Some(symbolica::domains::float::RealLike::to_f64(&r.to_float()))
        }
        _ => None,
    }
}
