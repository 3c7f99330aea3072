//! The kinematic class of a set of wheels, and each class's spec: inputs named
//! after the joints, the description's geometry as parameters, the twist (or
//! the wheels' constraints) written at the base link.
//!
//! Conventions: a wheel spinning positively about its axis `a` moves its
//! centre along `a x z` (rolling without slip); a steering joint's positive
//! angle turns left when its axis points up. Every formula is the planar
//! rigid-body relation v_wheel = v_base + omega x p for a wheel at p.
use crate::controller::{Controller, ControllerKind};
use crate::error::InitError;
use crate::geometry::{controller_value, FromUrdf, Quantity};
use crate::robot::{InputOut, InputRole, Robot};
use crate::wheels::Wheel;
use nalgebra::Vector2;
use std::path::Path;

/// Everything a class builder reads.
pub struct Context<'a> {
    pub file: &'a Path,
    pub wheels: &'a [Wheel],
    /// Joints that are driven (the controller's, else ros2_control's).
    pub driven: Vec<String>,
    /// Joints that follow another (`<mimic>`): not inputs of their own.
    pub mimics: Vec<String>,
    pub controller: Option<&'a Controller>,
}

/// A number computed from the description (a direction cosine, an offset)
/// without the last bits of rounding: 15 significant digits, and 0 below
/// 1e-12 (an axis that is "0 1 0" after rotating by pi/2 gives 6e-17).
pub fn tidy(v: f64) -> f64 {
    if v.abs() < 1e-12 {
        return 0.0;
    }
    format!("{v:.14e}").parse().unwrap_or(v)
}

/// A number printed so that reading it back gives the same f64.
pub fn num(v: f64) -> String {
    let s = format!("{v:?}");
    if s == "-0.0" {
        "0.0".into()
    } else {
        s
    }
}

/// `name` as a spec identifier: letters, digits and `_`, not starting with a
/// digit, not one of the spec's reserved words.
pub fn identifier(name: &str) -> String {
    let mut s: String = name
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    if s.starts_with(|c: char| c.is_ascii_digit()) || s.is_empty() {
        s.insert_str(0, "j_");
    }
    const RESERVED: [&str; 16] = [
        "x", "y", "theta", "dt", "xl", "yl", "vx", "vy", "omega", "pi", "e", "type", "fn", "self",
        "mod", "use",
    ];
    if RESERVED.contains(&s.as_str()) {
        s.push_str("_joint");
    }
    s
}

pub(crate) fn wheel_input(w: &Wheel, doc: String) -> InputOut {
    InputOut {
        name: identifier(&w.joint),
        column: w.joint.clone(),
        role: InputRole::Wheel,
        range: None,
        doc,
    }
}

/// +1 when the wheel's positive spin moves it forward (base x).
pub(crate) fn forward_sign(w: &Wheel) -> f64 {
    if w.rolling().x >= 0.0 {
        1.0
    } else {
        -1.0
    }
}

/// `name` (or `-name`).
pub(crate) fn signed(sign: f64, name: &str) -> String {
    if sign < 0.0 {
        format!("-{name}")
    } else {
        name.to_string()
    }
}

pub(crate) fn radius_of(w: &Wheel) -> FromUrdf {
    FromUrdf {
        value: w.radius,
        text: w.radius_text.clone(),
        source: format!(
            "line {}, radius of `{}`'s {}",
            w.radius_line, w.link, w.shape
        ),
    }
}

/// The wheels' joints as a source comment names them: "`a` line 12, `b` line 20".
pub(crate) fn joint_lines(wheels: &[&Wheel]) -> String {
    let each: Vec<String> = wheels
        .iter()
        .map(|w| format!("`{}` line {}", w.joint, w.line))
        .collect();
    each.join(", ")
}

pub(crate) fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    s / n.max(1) as f64
}

/// The twist at the base link from the twist at point c (base frame):
/// v_base = v_c + omega x (base - c). `vy_c`: the lateral velocity at c,
/// None where c has none (a fixed axle's centre).
pub(crate) fn at_base(
    (vx_c, vy_c): (&str, Option<&str>),
    c: Vector2<f64>,
    omega: &str,
    noise: (&str, &str, &str),
) -> [String; 3] {
    let vx = linear(0.0, &[(1.0, vx_c), (c.y, omega), (1.0, noise.0)]);
    let vy = match vy_c {
        Some(vy_c) => linear(0.0, &[(1.0, vy_c), (-c.x, omega), (1.0, noise.1)]),
        None if c.x.abs() > 1e-12 => linear(0.0, &[(-c.x, omega), (1.0, noise.1)]),
        None => "0".to_string(),
    };
    [vx, vy, format!("{omega} + {}", noise.2)]
}

pub(crate) const NOISE: (&str, &str, &str) = ("n_vx", "n_vy", "n_omega");

/// `c0 + c1*a + c2*b` with zero terms left out.
pub fn linear(c0: f64, terms: &[(f64, &str)]) -> String {
    let mut out = String::new();
    for (c, name) in terms
        .iter()
        .map(|(c, n)| (tidy(*c), n))
        .filter(|(c, _)| *c != 0.0)
    {
        let term = match c {
            1.0 => name.to_string(),
            -1.0 => format!("-{name}"),
            c => format!("{}*{name}", num(c)),
        };
        if out.is_empty() {
            out = term;
        } else if let Some(t) = term.strip_prefix('-') {
            out += &format!(" - {t}");
        } else {
            out += &format!(" + {term}");
        }
    }
    if c0.abs() > 1e-12 || out.is_empty() {
        if out.is_empty() {
            out = num(c0);
        } else if c0 < 0.0 {
            out += &format!(" - {}", num(-c0));
        } else {
            out += &format!(" + {}", num(c0));
        }
    }
    out
}

mod differential;
mod holonomic;
mod steered;
mod swerve;
pub use differential::differential;
pub use holonomic::{mecanum, omni};
pub use steered::{front_driven_steering, front_driven_tricycle, rear_driven_steering};
pub use swerve::swerve;
