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
];

/// Named constants of the language.
pub const CONSTANTS: &[&str] = &["pi"];

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

fn tokenize(src: &str) -> Result<Vec<(Tok, usize, usize)>, ParseError> {
    let bytes = src.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        let c = bytes[i] as char;
        if c.is_ascii_whitespace() {
            i += 1;
        } else if c.is_ascii_digit() || (c == '.' && i + 1 < bytes.len() && bytes[i + 1].is_ascii_digit()) {
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
            if text.parse::<f64>().is_err() {
                return Err(ParseError { offset: start, message: format!("malformed number `{text}`") });
            }
            out.push((Tok::Num(text.to_string()), start, i));
        } else if c.is_ascii_alphabetic() || c == '_' {
            let start = i;
            while i < bytes.len() && (bytes[i].is_ascii_alphanumeric() || bytes[i] == b'_') {
                i += 1;
            }
            out.push((Tok::Ident(src[start..i].to_string()), start, i));
        } else if "+-*/^(),".contains(c) {
            out.push((Tok::Op(c), i, i + 1));
            i += 1;
        } else {
            return Err(ParseError { offset: i, message: format!("unexpected character `{c}`") });
        }
    }
    Ok(out)
}

struct Parser<'a> {
    toks: Vec<(Tok, usize, usize)>,
    pos: usize,
    src: &'a str,
}

impl Parser<'_> {
    fn peek(&self) -> Option<&Tok> {
        self.toks.get(self.pos).map(|t| &t.0)
    }
    fn offset(&self) -> usize {
        self.toks.get(self.pos).map_or(self.src.len(), |t| t.1)
    }
    fn err<T>(&self, message: impl Into<String>) -> Result<T, ParseError> {
        Err(ParseError { offset: self.offset(), message: message.into() })
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
            lhs = Expr { kind: ExprKind::Bin(op, Box::new(lhs), Box::new(rhs)), span };
        }
        Ok(lhs)
    }

    fn prefix(&mut self) -> Result<Expr, ParseError> {
        let Some((tok, start, end)) = self.toks.get(self.pos).cloned() else {
            return self.err("expression ends too early");
        };
        self.pos += 1;
        match tok {
            Tok::Num(n) => Ok(Expr { kind: ExprKind::Num(n), span: (start, end) }),
            Tok::Op('-') => {
                let inner = self.expr(6)?;
                let span = (start, inner.span.1);
                Ok(Expr { kind: ExprKind::Neg(Box::new(inner)), span })
            }
            Tok::Op('+') => self.expr(6),
            Tok::Op('(') => {
                let inner = self.expr(0)?;
                let close = self.expect(')')?;
                Ok(Expr { kind: inner.kind, span: (start, close) })
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
                        return Err(ParseError { offset: start, message: format!("unknown function `{name}`") });
                    };
                    if args.len() != arity {
                        return Err(ParseError {
                            offset: start,
                            message: format!("`{name}` takes {arity} argument(s), got {}", args.len()),
                        });
                    }
                    Ok(Expr { kind: ExprKind::Call(name, args), span: (start, close) })
                } else {
                    Ok(Expr { kind: ExprKind::Var(name), span: (start, end) })
                }
            }
            Tok::Op(c) => Err(ParseError { offset: start, message: format!("unexpected `{c}`") }),
        }
    }
}

/// Parse one expression string.
pub fn parse(src: &str) -> Result<Expr, ParseError> {
    let toks = tokenize(src)?;
    let mut p = Parser { toks, pos: 0, src };
    let e = p.expr(0)?;
    if p.pos != p.toks.len() {
        return p.err("unexpected text after the expression");
    }
    Ok(e)
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
            ExprKind::Bin(op, a, b) => ExprKind::Bin(op.clone(), Box::new(a.substitute(map)), Box::new(b.substitute(map))),
            ExprKind::Call(f, args) => ExprKind::Call(f.clone(), args.iter().map(|a| a.substitute(map)).collect()),
        };
        Expr { kind, span: self.span }
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
                format!("{f}({})", args.iter().map(|a| a.to_source()).collect::<Vec<_>>().join(", "))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
        assert!(parse("atan2(x)").unwrap_err().message.contains("2 argument"));
        assert_eq!(parse("(a + b").unwrap_err().offset, 6);
        assert_eq!(parse("a $ b").unwrap_err().offset, 2);
    }
}
