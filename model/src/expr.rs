//! The math-expression language of spec files: `r_r*w_r/2 + atan2(y, x)^2`.
//!
//! A small Pratt parser written here rather than taken from a crate: the expression
//! crates on crates.io (meval, evalexpr, ...) evaluate but do not hand back an AST
//! with byte spans, and we need both the tree (to give to symbolica and to the
//! CasADi cross-check) and the spans (to report file:line:column on a bad spec).
use serde::{Deserialize, Serialize};

/// Functions the language knows, with their arity.
pub const FUNCTIONS: &[(&str, usize)] = &[
    ("sin", 1),
    ("cos", 1),
    ("tan", 1),
    ("atan", 1),
    ("atan2", 2),
    ("sqrt", 1),
    ("exp", 1),
    ("ln", 1),
    ("abs", 1),
    ("sign", 1),
];

/// Named constants of the language.
pub const CONSTANTS: &[&str] = &["pi"];

/// Longest expression accepted, in tokens. Kinematic expressions are a few dozen
/// tokens; the limit keeps every recursive pass over the tree (ours and symbolica's)
/// far from the stack's end, so a pathological spec gets a located error instead of
/// an abort.
pub const MAX_TOKENS: usize = 4000;
/// Deepest nesting of parentheses, unary signs and calls accepted.
pub const MAX_DEPTH: usize = 64;
/// Largest |exponent| of a power with a constant exponent: a kinematic model has
/// small powers; `x^1000000000` would make the derivation expand without end.
pub const MAX_EXPONENT: f64 = 64.0;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum BinOp {
    Add,
    Sub,
    Mul,
    Div,
    Pow,
}

/// An expression tree. `span` is the byte range in the expression string.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Expr {
    pub kind: ExprKind,
    pub span: (usize, usize),
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum ExprKind {
    /// A numeric literal, kept as written so the derivation can make it an exact rational.
    Num(String),
    Var(String),
    Neg(Box<Expr>),
    Bin(BinOp, Box<Expr>, Box<Expr>),
    Call(String, Vec<Expr>),
}

/// A parse error with the byte offset in the expression string.
#[derive(Debug, Clone, PartialEq)]
pub struct ParseError {
    pub offset: usize,
    pub message: String,
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Num(String),
    Ident(String),
    Op(char),
}

/// `holes`: an identifier may hold `{name}` parts (an effect template's
/// `{vx}`, `{0}`, `deadband_{input}`), which stay in the variable's name.
fn tokenize(src: &str, holes: bool) -> Result<Vec<(Tok, usize, usize)>, ParseError> {
    let in_name =
        |b: u8| b.is_ascii_alphanumeric() || b == b'_' || (holes && (b == b'{' || b == b'}'));
    let bytes = src.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        let c = bytes[i] as char;
        if c.is_ascii_whitespace() {
            i += 1;
        } else if c.is_ascii_digit()
            || (c == '.' && i + 1 < bytes.len() && bytes[i + 1].is_ascii_digit())
        {
            let start = i;
            while i < bytes.len() && (bytes[i].is_ascii_digit() || bytes[i] == b'.') {
                i += 1;
            }
            if i < bytes.len() && (bytes[i] == b'e' || bytes[i] == b'E') {
                let mut j = i + 1;
                if j < bytes.len() && (bytes[j] == b'+' || bytes[j] == b'-') {
                    j += 1;
                }
                if j < bytes.len() && bytes[j].is_ascii_digit() {
                    i = j;
                    while i < bytes.len() && bytes[i].is_ascii_digit() {
                        i += 1;
                    }
                }
            }
            let text = &src[start..i];
            match text.parse::<f64>() {
                Err(_) => {
                    return Err(ParseError {
                        offset: start,
                        message: format!("malformed number `{text}`"),
                    })
                }
                Ok(v) if !v.is_finite() => {
                    return Err(ParseError {
                        offset: start,
                        message: format!("number `{text}` is out of the range of a 64-bit float"),
                    })
                }
                Ok(_) => {}
            }
            out.push((Tok::Num(text.to_string()), start, i));
        } else if c.is_ascii_alphabetic() || c == '_' || (holes && c == '{') {
            let start = i;
            while i < bytes.len() && in_name(bytes[i]) {
                i += 1;
            }
            out.push((Tok::Ident(src[start..i].to_string()), start, i));
        } else if "+-*/^(),".contains(c) {
            out.push((Tok::Op(c), i, i + 1));
            i += 1;
        } else {
            // report the whole character (an omega, a non-breaking space), not a byte of it
            let ch = src[i..].chars().next().unwrap_or('?');
            return Err(ParseError {
                offset: i,
                message: format!("unexpected character `{ch}` (U+{:04X})", ch as u32),
            });
        }
    }
    Ok(out)
}

struct Parser<'a> {
    toks: Vec<(Tok, usize, usize)>,
    pos: usize,
    src: &'a str,
    /// Current nesting depth of `prefix` (parentheses, unary signs, calls).
    depth: usize,
}

impl Parser<'_> {
    fn peek(&self) -> Option<&Tok> {
        self.toks.get(self.pos).map(|t| &t.0)
    }
    fn offset(&self) -> usize {
        self.toks.get(self.pos).map_or(self.src.len(), |t| t.1)
    }
    fn err<T>(&self, message: impl Into<String>) -> Result<T, ParseError> {
        Err(ParseError {
            offset: self.offset(),
            message: message.into(),
        })
    }
    fn expect(&mut self, c: char) -> Result<usize, ParseError> {
        match self.toks.get(self.pos) {
            Some((Tok::Op(o), _, end)) if *o == c => {
                let end = *end;
                self.pos += 1;
                Ok(end)
            }
            _ => self.err(format!("expected `{c}`")),
        }
    }

    /// Pratt loop: `^` binds tighter than unary minus, which binds tighter than `*` `/`.
    fn expr(&mut self, min_bp: u8) -> Result<Expr, ParseError> {
        let mut lhs = self.prefix()?;
        loop {
            let (op, lbp, rbp) = match self.peek() {
                Some(Tok::Op('+')) => (BinOp::Add, 1, 2),
                Some(Tok::Op('-')) => (BinOp::Sub, 1, 2),
                Some(Tok::Op('*')) => (BinOp::Mul, 3, 4),
                Some(Tok::Op('/')) => (BinOp::Div, 3, 4),
                Some(Tok::Op('^')) => (BinOp::Pow, 8, 7), // right associative
                _ => break,
            };
            if lbp < min_bp {
                break;
            }
            self.pos += 1;
            let rhs = self.expr(rbp)?;
            let span = (lhs.span.0, rhs.span.1);
            lhs = Expr {
                kind: ExprKind::Bin(op, Box::new(lhs), Box::new(rhs)),
                span,
            };
        }
        Ok(lhs)
    }

    fn prefix(&mut self) -> Result<Expr, ParseError> {
        if self.depth >= MAX_DEPTH {
            return self.err(format!("expression nested too deeply (more than {MAX_DEPTH} levels of parentheses, signs or calls)"));
        }
        self.depth += 1;
        let e = self.prefix_inner();
        self.depth -= 1;
        e
    }

    fn prefix_inner(&mut self) -> Result<Expr, ParseError> {
        let Some((tok, start, end)) = self.toks.get(self.pos).cloned() else {
            return self.err("expression ends too early");
        };
        self.pos += 1;
        match tok {
            Tok::Num(n) => Ok(Expr {
                kind: ExprKind::Num(n),
                span: (start, end),
            }),
            Tok::Op('-') => {
                let inner = self.expr(6)?;
                let span = (start, inner.span.1);
                Ok(Expr {
                    kind: ExprKind::Neg(Box::new(inner)),
                    span,
                })
            }
            Tok::Op('+') => self.expr(6),
            Tok::Op('(') => {
                let inner = self.expr(0)?;
                let close = self.expect(')')?;
                Ok(Expr {
                    kind: inner.kind,
                    span: (start, close),
                })
            }
            Tok::Ident(name) => {
                if self.peek() == Some(&Tok::Op('(')) {
                    self.pos += 1;
                    let mut args = Vec::new();
                    if self.peek() != Some(&Tok::Op(')')) {
                        loop {
                            args.push(self.expr(0)?);
                            if self.peek() == Some(&Tok::Op(',')) {
                                self.pos += 1;
                            } else {
                                break;
                            }
                        }
                    }
                    let close = self.expect(')')?;
                    let Some(&(_, arity)) = FUNCTIONS.iter().find(|(f, _)| *f == name) else {
                        return Err(ParseError {
                            offset: start,
                            message: format!("unknown function `{name}`"),
                        });
                    };
                    if args.len() != arity {
                        return Err(ParseError {
                            offset: start,
                            message: format!(
                                "`{name}` takes {arity} argument(s), got {}",
                                args.len()
                            ),
                        });
                    }
                    Ok(Expr {
                        kind: ExprKind::Call(name, args),
                        span: (start, close),
                    })
                } else {
                    Ok(Expr {
                        kind: ExprKind::Var(name),
                        span: (start, end),
                    })
                }
            }
            Tok::Op(c) => Err(ParseError {
                offset: start,
                message: format!("unexpected `{c}`"),
            }),
        }
    }
}

/// Parse one expression string. Besides syntax, it rejects what no kinematic
/// model needs and what would break later stages: more than [`MAX_TOKENS`]
/// tokens, nesting deeper than [`MAX_DEPTH`], constant sub-expressions that are
/// not finite reals (`0/0`, `sqrt(-1)`, `ln(0)`, `10^400`) and constant exponents
/// beyond [`MAX_EXPONENT`].
pub fn parse(src: &str) -> Result<Expr, ParseError> {
    parse_with(src, false)
}

/// Parse an effect template: an expression whose names may hold `{hole}`
/// parts (see `spec/README.md`, effects), filled by substituting parsed
/// expressions, never by editing text.
pub fn parse_template(src: &str) -> Result<Expr, ParseError> {
    parse_with(src, true)
}

fn parse_with(src: &str, holes: bool) -> Result<Expr, ParseError> {
    let toks = tokenize(src, holes)?;
    if toks.len() > MAX_TOKENS {
        return Err(ParseError {
            offset: 0,
            message: format!(
                "expression too long: {} tokens (at most {MAX_TOKENS})",
                toks.len()
            ),
        });
    }
    let mut p = Parser {
        toks,
        pos: 0,
        src,
        depth: 0,
    };
    let e = p.expr(0)?;
    if p.pos != p.toks.len() {
        return p.err("unexpected text after the expression");
    }
    check_constants(&e)?;
    Ok(e)
}

/// Every constant sub-expression must be a finite real, and constant exponents
/// small. Returns the value of `e` when it is constant.
fn check_constants(e: &Expr) -> Result<Option<f64>, ParseError> {
    let bad = |msg: String| ParseError {
        offset: e.span.0,
        message: msg,
    };
    let value = match &e.kind {
        ExprKind::Num(n) => n.parse::<f64>().ok(),
        ExprKind::Var(v) => CONSTANTS
            .contains(&v.as_str())
            .then_some(std::f64::consts::PI),
        ExprKind::Neg(a) => check_constants(a)?.map(|v| -v),
        ExprKind::Bin(op, a, b) => {
            let (va, vb) = (check_constants(a)?, check_constants(b)?);
            if let (BinOp::Pow, Some(x)) = (op, vb) {
                if x.abs() > MAX_EXPONENT {
                    return Err(ParseError {
                        offset: b.span.0,
                        message: format!(
                            "exponent {x} is too large (|exponent| <= {MAX_EXPONENT})"
                        ),
                    });
                }
            }
            match (va, vb) {
                (Some(x), Some(y)) => Some(apply_bin(op, x, y)),
                _ => None,
            }
        }
        ExprKind::Call(f, args) => {
            let vals = args
                .iter()
                .map(check_constants)
                .collect::<Result<Vec<_>, _>>()?;
            vals.iter()
                .copied()
                .collect::<Option<Vec<f64>>>()
                .map(|v| apply_call(f, &v))
        }
    };
    match value {
        Some(v) if !v.is_finite() => Err(bad(format!(
            "`{}` is not a finite real number (it evaluates to {v})",
            e.to_source()
        ))),
        v => Ok(v),
    }
}

fn apply_bin(op: &BinOp, x: f64, y: f64) -> f64 {
    match op {
        BinOp::Add => x + y,
        BinOp::Sub => x - y,
        BinOp::Mul => x * y,
        BinOp::Div => x / y,
        BinOp::Pow => x.powf(y),
    }
}

fn apply_call(f: &str, a: &[f64]) -> f64 {
    match f {
        "sin" => a[0].sin(),
        "cos" => a[0].cos(),
        "tan" => a[0].tan(),
        "atan" => a[0].atan(),
        "atan2" => a[0].atan2(a[1]),
        "sqrt" => a[0].sqrt(),
        "exp" => a[0].exp(),
        "ln" => a[0].ln(),
        "abs" => a[0].abs(),
        "sign" => crate::ir::sign(a[0]),
        _ => f64::NAN,
    }
}

impl Expr {
    /// Every variable name used, with its span, in order of appearance.
    pub fn variables(&self) -> Vec<(&str, (usize, usize))> {
        let mut out = Vec::new();
        self.walk(&mut |e| {
            if let ExprKind::Var(v) = &e.kind {
                out.push((v.as_str(), e.span));
            }
        });
        out
    }

    fn walk<'a>(&'a self, f: &mut impl FnMut(&'a Expr)) {
        f(self);
        match &self.kind {
            ExprKind::Neg(a) => a.walk(f),
            ExprKind::Bin(_, a, b) => {
                a.walk(f);
                b.walk(f);
            }
            ExprKind::Call(_, args) => args.iter().for_each(|a| a.walk(f)),
            _ => {}
        }
    }

    /// Replace variables by expressions (used to splice definitions and effect patches).
    pub fn substitute(&self, map: &dyn Fn(&str) -> Option<Expr>) -> Expr {
        let kind = match &self.kind {
            ExprKind::Var(v) => match map(v) {
                Some(e) => return e,
                None => ExprKind::Var(v.clone()),
            },
            ExprKind::Num(n) => ExprKind::Num(n.clone()),
            ExprKind::Neg(a) => ExprKind::Neg(Box::new(a.substitute(map))),
            ExprKind::Bin(op, a, b) => ExprKind::Bin(
                op.clone(),
                Box::new(a.substitute(map)),
                Box::new(b.substitute(map)),
            ),
            ExprKind::Call(f, args) => {
                ExprKind::Call(f.clone(), args.iter().map(|a| a.substitute(map)).collect())
            }
        };
        Expr {
            kind,
            span: self.span,
        }
    }

    /// Numeric value with variables from `var` (None: unknown variable). Used to
    /// inspect a model's structure without symbolic algebra (which wheel turns
    /// the body which way), never for the kernels themselves.
    pub fn eval(&self, var: &dyn Fn(&str) -> Option<f64>) -> Option<f64> {
        Some(match &self.kind {
            ExprKind::Num(n) => n.parse().ok()?,
            ExprKind::Var(v) if v == "pi" => std::f64::consts::PI,
            ExprKind::Var(v) => var(v)?,
            ExprKind::Neg(a) => -a.eval(var)?,
            ExprKind::Bin(op, a, b) => apply_bin(op, a.eval(var)?, b.eval(var)?),
            ExprKind::Call(f, args) => apply_call(
                f,
                &args
                    .iter()
                    .map(|a| a.eval(var))
                    .collect::<Option<Vec<_>>>()?,
            ),
        })
    }

    /// Is this the constant zero (as a spec writes `vy = "0"`)?
    pub fn is_zero(&self) -> bool {
        self.variables().is_empty() && self.eval(&|_| None) == Some(0.0)
    }

    /// Render back to the spec language (fully parenthesised where needed).
    pub fn to_source(&self) -> String {
        match &self.kind {
            ExprKind::Num(n) => n.clone(),
            ExprKind::Var(v) => v.clone(),
            ExprKind::Neg(a) => format!("(-{})", a.to_source()),
            ExprKind::Bin(op, a, b) => {
                let o = match op {
                    BinOp::Add => "+",
                    BinOp::Sub => "-",
                    BinOp::Mul => "*",
                    BinOp::Div => "/",
                    BinOp::Pow => "^",
                };
                format!("({} {o} {})", a.to_source(), b.to_source())
            }
            ExprKind::Call(f, args) => {
                format!(
                    "{f}({})",
                    args.iter()
                        .map(|a| a.to_source())
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            }
        }
    }
}

/// Binding power of a node as a printed operand: how tightly it holds
/// together (atoms most).
fn binding(e: &Expr) -> u8 {
    match &e.kind {
        ExprKind::Bin(BinOp::Add | BinOp::Sub, ..) => 1,
        ExprKind::Bin(BinOp::Mul | BinOp::Div, ..) => 3,
        ExprKind::Neg(_) => 6,
        ExprKind::Bin(BinOp::Pow, ..) => 8,
        _ => 10,
    }
}

/// The spec language as a person writes it: parentheses only where the
/// grouping needs them, so `parse(e.to_string())` is `e` again (up to spans).
/// What a spec file gets when an effect rewrites one of its expressions.
impl std::fmt::Display for Expr {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let operand = |f: &mut std::fmt::Formatter<'_>, e: &Expr, wrap: bool| {
            if wrap {
                write!(f, "({e})")
            } else {
                write!(f, "{e}")
            }
        };
        match &self.kind {
            ExprKind::Num(n) => write!(f, "{n}"),
            ExprKind::Var(v) => write!(f, "{v}"),
            // a sign binds looser than `^` and tighter than `*`: -x^2 is -(x^2)
            ExprKind::Neg(a) => {
                write!(f, "-")?;
                operand(f, a, binding(a) < 8)
            }
            ExprKind::Bin(op, a, b) => {
                let (sym, left, right) = match op {
                    BinOp::Add => (" + ", 1, 2),
                    BinOp::Sub => (" - ", 1, 2),
                    BinOp::Mul => ("*", 3, 4),
                    BinOp::Div => ("/", 3, 4),
                    BinOp::Pow => ("^", 9, 8), // right associative
                };
                // a signed operand is wrapped anywhere but first, so that
                // `a*-b` and `a - -b` read as what they are
                let signed = |e: &Expr| matches!(e.kind, ExprKind::Neg(_));
                operand(f, a, binding(a) < left || (signed(a) && *op == BinOp::Pow))?;
                write!(f, "{sym}")?;
                operand(f, b, binding(b) < right || signed(b))
            }
            ExprKind::Call(name, args) => {
                write!(f, "{name}(")?;
                for (k, a) in args.iter().enumerate() {
                    if k > 0 {
                        write!(f, ", ")?;
                    }
                    write!(f, "{a}")?;
                }
                write!(f, ")")
            }
        }
    }
}

impl Expr {
    /// The same expression without the terms an effect's template leaves
    /// when it fills a hole with a spec's `0` (`0 + k*vx`) or `1`: `0 + x`,
    /// `x + 0`, `x - 0`, `1*x`, `x*1` and `x/1` become `x`, so a spec an
    /// effect rewrote reads as a person would write it. The value is the
    /// same everywhere.
    pub fn without_identities(&self) -> Expr {
        let is =
            |e: &Expr, v: f64| matches!(&e.kind, ExprKind::Num(n) if n.parse::<f64>() == Ok(v));
        let kind = match &self.kind {
            ExprKind::Bin(op, a, b) => {
                let (a, b) = (a.without_identities(), b.without_identities());
                match op {
                    BinOp::Add if is(&a, 0.0) => return b,
                    BinOp::Add | BinOp::Sub if is(&b, 0.0) => return a,
                    BinOp::Mul if is(&a, 1.0) => return b,
                    BinOp::Mul | BinOp::Div if is(&b, 1.0) => return a,
                    _ => ExprKind::Bin(op.clone(), Box::new(a), Box::new(b)),
                }
            }
            ExprKind::Neg(a) => ExprKind::Neg(Box::new(a.without_identities())),
            ExprKind::Call(f, args) => ExprKind::Call(
                f.clone(),
                args.iter().map(Expr::without_identities).collect(),
            ),
            k => k.clone(),
        };
        Expr {
            kind,
            span: self.span,
        }
    }

    /// The same tree, wherever it was written: spans are ignored.
    pub fn same_as(&self, other: &Expr) -> bool {
        match (&self.kind, &other.kind) {
            (ExprKind::Num(a), ExprKind::Num(b)) | (ExprKind::Var(a), ExprKind::Var(b)) => a == b,
            (ExprKind::Neg(a), ExprKind::Neg(b)) => a.same_as(b),
            (ExprKind::Bin(o, a, b), ExprKind::Bin(p, c, d)) => {
                o == p && a.same_as(c) && b.same_as(d)
            }
            (ExprKind::Call(f, a), ExprKind::Call(g, b)) => {
                f == g && a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.same_as(y))
            }
            _ => false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Printing keeps the tree: every grouping the parser distinguishes
    /// survives a round trip, with no more parentheses than it needs.
    #[test]
    fn printed_expressions_parse_back_to_the_same_tree() {
        for (src, printed) in [
            ("a + b*c^2^3 - -d", "a + b*c^2^3 - (-d)"),
            ("(a + b)*(c - d)/(e*f)", "(a + b)*(c - d)/(e*f)"),
            ("a - (b - c) - (d + e)", "a - (b - c) - (d + e)"),
            ("a/(b/c)/d", "a/(b/c)/d"),
            ("(a^b)^c + a^b^c", "(a^b)^c + a^b^c"),
            (
                "-x^2 + (-x)^2 + -(x*y) + (-x)*y",
                "-x^2 + (-x)^2 + (-(x*y)) + -x*y",
            ),
            ("a*-b + a^-b + --a", "a*(-b) + a^(-b) + (-(-a))"),
            (
                "atan2(y - 1, -x)*sin(theta)^2",
                "atan2(y - 1, -x)*sin(theta)^2",
            ),
            ("((r*(wr + wl))/2)", "r*(wr + wl)/2"),
        ] {
            let e = parse(src).unwrap();
            assert_eq!(e.to_string(), printed, "{src}");
            let back = parse(&e.to_string()).unwrap();
            assert!(back.same_as(&e), "{src} -> {e} -> {back:?}");
        }
        assert!(!parse("a - b - c")
            .unwrap()
            .same_as(&parse("a - (b - c)").unwrap()));
    }

    #[test]
    fn templates_keep_their_holes_in_names() {
        let t = parse_template("({vx}) + k*{0} - deadband_{input}").unwrap();
        let names: Vec<&str> = t.variables().into_iter().map(|v| v.0).collect();
        assert_eq!(names, ["{vx}", "k", "{0}", "deadband_{input}"]);
        assert!(parse("{vx} + 1").is_err());
    }

    #[test]
    fn precedence_and_spans() {
        let e = parse("a + b*c^2^3 - -d").unwrap();
        assert_eq!(e.to_source(), "((a + (b * (c ^ (2 ^ 3)))) - (-d))");
        let e = parse("-x^2").unwrap();
        assert_eq!(e.to_source(), "(-(x ^ 2))");
        let e = parse("atan2(y, x)").unwrap();
        assert_eq!(e.span, (0, 11));
        assert_eq!(e.variables(), vec![("y", (6, 7)), ("x", (9, 10))]);
    }

    #[test]
    fn errors_point_at_offset() {
        assert_eq!(parse("a + * b").unwrap_err().offset, 4);
        assert_eq!(parse("foo(x)").unwrap_err().offset, 0);
        assert!(parse("atan2(x)")
            .unwrap_err()
            .message
            .contains("2 argument"));
        assert_eq!(parse("(a + b").unwrap_err().offset, 6);
        assert_eq!(parse("a $ b").unwrap_err().offset, 2);
    }

    #[test]
    fn pathological_expressions_are_rejected_with_an_offset() {
        let deep = format!("{}x{}", "(".repeat(1_000), ")".repeat(1_000));
        assert!(parse(&format!("{}x{}", "(".repeat(10_000), ")".repeat(10_000))).is_err());
        assert!(parse(&deep)
            .unwrap_err()
            .message
            .contains("nested too deeply"));
        assert!(parse(&format!("{}x", "-".repeat(1_000)))
            .unwrap_err()
            .message
            .contains("nested too deeply"));
        let long = vec!["x"; 48_000].join(" + ");
        assert!(parse(&long).unwrap_err().message.contains("too long"));
        assert!(parse("x*1e400")
            .unwrap_err()
            .message
            .contains("out of the range"));
        let e = parse("n_r*10^400").unwrap_err();
        assert!(e.offset == 7 && e.message.contains("exponent 400"), "{e:?}");
        assert!(parse("2^2^2^2^2^2").is_err());
        assert!(parse("x*10^60^2").unwrap_err().message.contains("exponent"));
        assert!(parse("x*(1e300*1e300)")
            .unwrap_err()
            .message
            .contains("finite real"));
        assert!(parse("x + 0/0")
            .unwrap_err()
            .message
            .contains("finite real"));
        assert_eq!(parse("y + sqrt(-1)").unwrap_err().offset, 4);
        assert!(parse("ln(0)*x").is_err());
        assert!(parse("n_r^1000000000")
            .unwrap_err()
            .message
            .contains("exponent"));
        assert!(parse("x ω").unwrap_err().message.contains("`ω`"));
        // ordinary models still parse, with their values
        let e = parse("2*pi*x^2 - sqrt(4)").unwrap();
        assert_eq!(
            e.eval(&|v| (v == "x").then_some(1.0)),
            Some(2.0 * std::f64::consts::PI - 2.0)
        );
        assert!(parse("0").unwrap().is_zero() && !parse("x").unwrap().is_zero());
    }
}
