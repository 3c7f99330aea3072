//! `fit --export ros2-yaml PATH`: the calibrated values where a robot's
//! configuration wants them. A differential drive gets the parameters of the
//! standard ROS 2 `diff_drive_controller`; any other model a generic list of
//! every calibrated parameter with its standard deviation.
//!
//! `fit --export spec PATH`: the spec itself with the calibrated values as
//! its nominals, for the commands that run a model as its spec says
//! (`localize`, `compare`, `simulate`).
//!
//! The YAML is written with `format!`: two flat, fixed layouts of numbers and
//! identifiers, which a YAML library (serde_yaml is unmaintained) would not make
//! safer.
use kinegen_analysis::estimation::fit::FitResult;
use kinegen_analysis::model_on_log::model::Runner;
use kinegen_model::effects::{has, inputs_of, Capability, InputClass};
use kinegen_model::spec::Model;
use std::path::Path;

/// The body twist's derivatives with respect to each input at `p` (the twist of
/// a wheeled base is linear in its wheel rates): (dvx/du, domega/du) per input.
fn twist_gains(r: &Runner, p: &[f64]) -> Vec<(f64, f64)> {
    let tw = r.ir.twist();
    let n = r.ir.inputs.len();
    let (mut out, mut scratch) = ([0.0; 3], Vec::new());
    let mut at = |u: &[f64]| {
        r.eval_into(tw, &[u, p], &mut out, &mut scratch);
        out
    };
    let zero = at(&vec![0.0; n]);
    (0..n)
        .map(|k| {
            let mut u = vec![0.0; n];
            u[k] = 1.0;
            let t = at(&u);
            (t[0] - zero[0], t[2] - zero[2])
        })
        .collect()
}

/// Wheel separation and the right and left effective radii (m per input unit)
/// of a differential drive at `p`, averaged over the wheels of each side.
fn geometry(r: &Runner, p: &[f64], right: &[usize], left: &[usize]) -> (f64, f64, f64) {
    let g = twist_gains(r, p);
    let mean = |v: Vec<f64>| v.iter().sum::<f64>() / v.len() as f64;
    // vx = (k_r u_r + k_l u_l)/2 and omega = (k_r u_r - k_l u_l)/b per side
    let k_r = mean(
        right
            .iter()
            .map(|&i| 2.0 * g[i].0 * right.len() as f64)
            .collect(),
    );
    let k_l = mean(
        left.iter()
            .map(|&i| 2.0 * g[i].0 * left.len() as f64)
            .collect(),
    );
    let b = mean(
        right
            .iter()
            .map(|&i| 2.0 * g[i].0 / g[i].1)
            .chain(left.iter().map(|&i| -2.0 * g[i].0 / g[i].1))
            .collect(),
    );
    (b, k_r, k_l)
}

/// The YAML text for `res`, calibrated from `r` (nominal values in `r.p`).
pub fn ros2_yaml(spec: &Path, r: &Runner, res: &FitResult) -> Result<String, String> {
    let model = Model::load(spec).map_err(|e| e.to_string())?;
    if let Some(target) = &model.controller {
        return controller_yaml(spec, &model, target, r, res);
    }
    let index = |names: Vec<String>| -> Vec<usize> {
        names
            .iter()
            .filter_map(|n| r.ir.inputs.iter().position(|i| &i.name == n))
            .collect()
    };
    let (right, left) = (
        index(inputs_of(&model, InputClass::RightWheel)),
        index(inputs_of(&model, InputClass::LeftWheel)),
    );
    let differential = has(&model, Capability::Differential).is_ok()
        && has(&model, Capability::Nonholonomic).is_ok()
        && has(&model, Capability::Steering).is_err()
        && right.len() + left.len() == r.ir.inputs.len();
    let head = format!(
        "# kinegen fit: model `{}` from {}\n",
        r.ir.name,
        spec.display()
    );
    // every calibrated parameter with its uncertainty, for any spec (after the
    // controller's parameters for a differential drive, which name only a few)
    let mut calibration = format!(
        "kinegen_calibration:\n  model: {}\n  parameters:\n",
        r.ir.name
    );
    let rp = r.ir.runtime_params();
    for (k, &i) in res.free.iter().enumerate() {
        let std = res.std.get(k).copied().filter(|s| s.is_finite());
        calibration += &format!(
            "    {}:\n      value: {}\n      std: {}\n      nominal: {}\n      unit: \"{}\"\n",
            r.names[i],
            res.p[i],
            std.map_or("null # not identified by these logs".into(), |s| format!(
                "{s}"
            )),
            r.p[i],
            rp[i].unit.replace('"', "'"),
        );
    }
    if differential {
        // as comments: a ROS 2 parameter file holds `ros__parameters` of nodes only
        let calibration: String = calibration.lines().map(|l| format!("# {l}\n")).collect();
        let (b0, kr0, kl0) = geometry(r, &r.p, &right, &left);
        let (b, kr, kl) = geometry(r, &res.p, &right, &left);
        let in_rad = r.ir.inputs.iter().all(|i| i.unit == "rad/s");
        let radius = 0.5 * (kr0 + kl0);
        let (radius_line, rr, rl) = if in_rad {
            (
                format!("    wheel_radius: {radius:.9}\n"),
                kr / radius,
                kl / radius,
            )
        } else {
            (
                format!(
                    "    # wheel_radius: keep your controller's value (the spec's inputs are in {}, not rad/s);\n    # the multipliers below are relative to the spec's nominal radii\n",
                    r.ir.inputs[right[0]].unit
                ),
                kr / kr0,
                kl / kl0,
            )
        };
        return Ok(format!(
            "{head}# ROS 2 diff_drive_controller parameters: separation and radii from the calibrated\n# kinematics (multipliers: calibrated over nominal)\ndiff_drive_controller:\n  ros__parameters:\n    wheel_separation: {b0:.9}\n{radius_line}    wheel_separation_multiplier: {:.9}\n    left_wheel_radius_multiplier: {rl:.9}\n    right_wheel_radius_multiplier: {rr:.9}\n{calibration}",
            b / b0
        ));
    }
    Ok(format!("{head}{calibration}"))
}

/// A spec with a `[controller]` (written by `kinegen init`): the controller
/// file it came from with each of its values set from the calibration, every
/// other line as it was; a fresh file of the same structure when the original
/// is not where the spec says.
fn controller_yaml(
    spec: &Path,
    model: &Model,
    target: &kinegen_model::spec::ControllerTarget,
    r: &Runner,
    res: &FitResult,
) -> Result<String, String> {
    let value_of = |name: &str| -> Option<f64> {
        match r.names.iter().position(|n| n == name) {
            Some(i) => Some(res.p[i]),
            None => model
                .params
                .iter()
                .find(|p| p.name == name)
                .map(|p| p.nominal),
        }
    };
    let mut values = Vec::new();
    for (key, e) in &target.values {
        let v = e.eval(&value_of).filter(|v| v.is_finite()).ok_or_else(|| {
            format!(
                "{}: [controller.values] {key}: not a finite number at the calibrated parameters",
                spec.display()
            )
        })?;
        // always a decimal point: ROS 2 types `1` as an integer, and the
        // controllers refuse an integer where they declare a double
        let mut text = format!("{v:.9}").trim_end_matches('0').to_string();
        if text.ends_with('.') {
            text.push('0');
        }
        values.push((key.clone(), text));
    }
    let mut head = format!(
        "# calibrated by kinegen fit: model `{}` from {}\n",
        r.ir.name,
        spec.display()
    );
    for (k, &i) in res.free.iter().enumerate() {
        let std = res.std.get(k).copied().filter(|s| s.is_finite());
        head += &format!(
            "#   {} = {} {} (nominal {})\n",
            r.names[i],
            res.p[i],
            std.map_or("(not identified by these logs)".into(), |s| format!(
                "+- {s:.2e}"
            )),
            r.p[i]
        );
    }
    let file = spec.parent().unwrap_or(Path::new("")).join(&target.file);
    let original = (!target.file.is_empty())
        .then(|| std::fs::read_to_string(&file).ok())
        .flatten();
    let body = match original
        .as_deref()
        .and_then(|t| kinegen_init::controller_write::rewrite(t, &target.node, &values))
    {
        Some(b) => {
            head += &format!("# from {} with the calibrated values\n", file.display());
            b
        }
        None => kinegen_init::controller_write::fresh(&target.node, &target.type_name, &values),
    };
    Ok(format!("{head}{body}"))
}

/// The spec at `spec` with every parameter `res` calibrated and identified
/// at its calibrated value (one the logs did not identify keeps its
/// nominal), headed by a comment saying so.
pub fn fitted_spec(spec: &Path, r: &Runner, res: &FitResult) -> Result<String, String> {
    let model = Model::load(spec).map_err(|e| e.to_string())?;
    let values: Vec<(&str, f64)> = res
        .free
        .iter()
        .enumerate()
        .filter(|(k, _)| res.std.get(*k).is_some_and(|s| s.is_finite()))
        .map(|(_, &i)| (r.names[i].as_str(), res.p[i]))
        .collect();
    let text = kinegen_model::effects::with_nominals(&model, &values).map_err(|e| e.to_string())?;
    let names: Vec<&str> = values.iter().map(|v| v.0).collect();
    Ok(format!(
        "# calibrated by kinegen fit from {}: {}\n{text}",
        spec.display(),
        names.join(", ")
    ))
}
