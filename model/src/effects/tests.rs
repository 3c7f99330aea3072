//! The catalogue on users' specs: applicability, typed application, the
//! spec text it renders.
use super::*;
use crate::expr::Expr;
use crate::spec::{Kinematics, DEFAULT_POSE_COLUMNS};
use std::collections::BTreeMap;

/// The compiled-in catalogue is every file of `spec/effects/`, each by
/// its own name and text: an effect added there and not here (or the
/// reverse) would exist for the tests and not for users.
#[test]
fn the_bundled_catalogue_is_the_effects_folder() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../spec/effects");
    let mut files: Vec<(String, String)> = std::fs::read_dir(&dir)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .map(|p| {
            let name = p.file_name().unwrap().to_string_lossy().to_string();
            (name, std::fs::read_to_string(&p).unwrap())
        })
        .collect();
    files.sort();
    let mut bundled: Vec<(String, String)> = BUNDLED
        .iter()
        .map(|(f, t)| (f.to_string(), t.to_string()))
        .collect();
    bundled.sort();
    let names = |v: &[(String, String)]| v.iter().map(|x| x.0.clone()).collect::<Vec<_>>();
    assert_eq!(
        names(&bundled),
        names(&files),
        "BUNDLED against spec/effects/"
    );
    assert_eq!(bundled, files);
}

fn model(text: &str) -> Model {
    Model::parse(Path::new("robot.toml"), text).unwrap()
}

const SKID: &str = r#"# a user's skid steer
name = "skid4"
state = ["x", "y", "theta"]

[[input]]   # front right
name = "fr"
column = "enc_fr"
kind = "cumulative"

[[input]]
name = "rr"
column = "enc_rr"
kind = "cumulative"

[[input]]
name = "fl"
column = "enc_fl"
kind = "cumulative"

[[input]]
name = "rl"
column = "enc_rl"
kind = "cumulative"

[[parameter]]
name = "radius"
nominal = 0.1
unit = "m"
min = 0.0

[[parameter]]
name = "track"
nominal = 0.5
unit = "m"
min = 0.0

[motion]
vx = "radius*(fr + rr + fl + rl)/4"
vy = "0"
omega = "radius*(fr + rr - fl - rl)/(2*track)"   # effective track
"#;

/// A spec that declares its own measurement delay (any name) is not offered
/// a second one: the catalogue's time_offset says why, and a spec with a
/// second delay is refused.
#[test]
fn a_declared_delay_rules_out_time_offset() {
    let cat = catalogue(&[]).unwrap();
    let delayed = SKID.replace(
        "[motion]",
        "[[parameter]]\nname = \"lag\"\nnominal = 0.0\nunit = \"s\"\nmeasurement_delay = true\n\n[motion]",
    );
    let m = model(&delayed);
    let eff = find(&cat, "time_offset").unwrap();
    assert!(
        matches!(eff.applicability(&m), Applicability::NotApplicable(w) if w.contains("already declares a measurement delay (`lag`)"))
    );
    assert_eq!(eff.applicability(&model(SKID)), Applicability::Applies);
}

#[test]
fn applicability_follows_structure_not_names() {
    let cat = catalogue(&[]).unwrap();
    let m = model(SKID);
    let verdict = |n: &str| find(&cat, n).unwrap().applicability(&m);
    assert_eq!(inputs_of(&m, InputClass::RightWheel), ["fr", "rr"]);
    assert_eq!(inputs_of(&m, InputClass::LeftWheel), ["fl", "rl"]);
    for n in [
        "lateral_slip",
        "wheel_misalignment",
        "wheel_radius_asymmetry",
        "wheelbase_scale",
        "sensor_offset",
        "time_offset",
        "longitudinal_slip",
    ] {
        assert_eq!(verdict(n), Applicability::Applies, "{n}");
    }
    assert!(
        matches!(verdict("steering_offset"), Applicability::NotApplicable(w) if w.contains("steering"))
    );
    assert!(matches!(verdict("gyro_bias"), Applicability::NotApplicable(w) if w.contains("gyro")));
}

#[test]
fn apply_keeps_comments_and_order_and_patches_both_sides() {
    let cat = catalogue(&[]).unwrap();
    let m = model(SKID);
    let eff = find(&cat, "wheel_radius_asymmetry").unwrap();
    let vals = BTreeMap::from([("radius_asym".to_string(), 0.01)]);
    let out = eff.with_values(&m, &vals).unwrap().source;
    assert!(
        out.starts_with("# a user's skid steer\nname = \"skid4\""),
        "{out}"
    );
    assert!(
        out.contains("[[input]]   # front right") && out.contains("# effective track"),
        "{out}"
    );
    let after = Model::parse(Path::new("robot.toml"), &out).unwrap();
    assert_eq!(after.effects, ["wheel_radius_asymmetry"]);
    let p = after
        .params
        .iter()
        .find(|p| p.name == "radius_asym")
        .unwrap();
    assert_eq!(p.nominal, 0.01);
    let Kinematics::Twist(t) = &after.kinematics else {
        panic!()
    };
    let w = t[2].to_source();
    assert!(
        w.contains("(fr * (1 + radius_asym))") && w.contains("(rl * (1 - radius_asym))"),
        "{w}"
    );
    let err = eff
        .with_values(&m, &BTreeMap::from([("zz".to_string(), 1.0)]))
        .unwrap_err();
    assert!(
        matches!(&err, ApplyError::NoSuchParameter { parameter, .. } if parameter == "zz"),
        "{err}"
    );
    assert!(err.to_string().contains("no parameter `zz`"), "{err}");
    assert_eq!(eff.applicability(&after), Applicability::AlreadyIn);
}

/// A steering encoder in ticks: the offset is in ticks, bounded by an eighth
/// of the declared range, and the declared inverse adds it back.
#[test]
fn steering_offset_is_in_the_encoders_units_and_keeps_the_inverse() {
    let cat = catalogue(&[]).unwrap();
    let m = model(include_str!("../../../tests/user_specs/fwd_tricycle.toml"));
    let eff = find(&cat, "steering_offset").unwrap();
    let params = eff.parameters_for(&m);
    assert_eq!(params.len(), 1);
    assert_eq!(params[0].unit, "tick");
    assert_eq!(params[0].max, Some(225.0)); // range [-900, 900] / 8
    let text = eff
        .with_values(&m, &BTreeMap::from([("steer_offset_steer".into(), 40.0)]))
        .unwrap()
        .source;
    let after = Model::parse(Path::new("robot.toml"), &text).unwrap();
    assert!(
        text.contains("atan2(L*omega*vx, vx^2)/steer_gain + steer_offset_steer\""),
        "inverse not patched:\n{text}"
    );
    assert_eq!(
        after
            .params
            .iter()
            .find(|p| p.name == "steer_offset_steer")
            .unwrap()
            .unit,
        "tick"
    );
    // an effect that substitutes the wheels without an inverse template drops it
    let mut bare = find(&cat, "wheel_radius_asymmetry").unwrap().clone();
    for e in &mut bare.each_input {
        e.inverse = None;
    }
    let skid = model(include_str!("../../../tests/user_specs/skid4.toml"));
    assert!(skid.source.contains("[inverse]"));
    let text = bare.with_values(&skid, &BTreeMap::new()).unwrap().source;
    assert!(!text.contains("[inverse]"), "{text}");
    // with the bundled templates it is kept, divided by the asymmetry
    let wra = find(&cat, "wheel_radius_asymmetry").unwrap();
    let text = wra.with_values(&skid, &BTreeMap::new()).unwrap().source;
    assert!(
        text.contains("[inverse]") && text.contains("/(1 + radius_asym)\""),
        "{text}"
    );
}

#[test]
fn sensor_offset_moves_every_exteroceptive_sensor_with_bounds_that_scale() {
    let cat = catalogue(&[]).unwrap();
    let text = format!(
        "{SKID}\n[[observation]]\nname = \"lidar\"\nlandmark = true\ncolumns = [\"range\", \"bearing\"]\nexpr = [\"sqrt((xl - x)^2 + (yl - y)^2)\", \"atan2(yl - y, xl - x) - theta\"]\nangle = [false, true]\n"
    );
    let m = model(&text);
    let eff = find(&cat, "sensor_offset").unwrap();
    let names: Vec<String> = eff.parameters_for(&m).into_iter().map(|p| p.name).collect();
    assert_eq!(
        names,
        ["sensor_dx", "sensor_dy", "rb_sensor_dx", "rb_sensor_dy"]
    );
    let after = Model::parse(
        Path::new("robot.toml"),
        &eff.with_values(&m, &BTreeMap::from([("sensor_dx".into(), 1.8)]))
            .unwrap()
            .source,
    )
    .unwrap();
    assert_eq!(
        after
            .observations
            .iter()
            .map(|o| o.role)
            .collect::<Vec<_>>(),
        [ObservationRole::RangeBearing, ObservationRole::Pose]
    );
    let pose = after
        .observations
        .iter()
        .find(|o| o.role == ObservationRole::Pose)
        .unwrap();
    assert_eq!(pose.columns, DEFAULT_POSE_COLUMNS);
    let lidar = after
        .observations
        .iter()
        .find(|o| o.name == "lidar")
        .unwrap();
    assert!(lidar.exprs[0].to_source().contains("rb_sensor_dx"));
    let dx = after.params.iter().find(|p| p.name == "sensor_dx").unwrap();
    assert_eq!((dx.nominal, dx.min, dx.max), (1.8, Some(-5.0), Some(5.0)));
}

/// Two models say the same: declarations, every expression (as trees),
/// observations, inverse and effects; where each was written is ignored.
fn same_model(a: &Model, b: &Model) -> Result<(), String> {
    let exprs =
        |x: &[Expr], y: &[Expr]| x.len() == y.len() && x.iter().zip(y).all(|(p, q)| p.same_as(q));
    let checks: [(&str, bool); 8] = [
        ("inputs", same_json(&a.inputs, &b.inputs)),
        ("parameters", same_json(&a.params, &b.params)),
        ("noise", same_json(&a.noise, &b.noise)),
        (
            "definitions",
            a.defines.len() == b.defines.len()
                && a.defines
                    .iter()
                    .zip(&b.defines)
                    .all(|(p, q)| p.0 == q.0 && p.1.same_as(&q.1)),
        ),
        (
            "kinematics",
            match (&a.kinematics, &b.kinematics) {
                (Kinematics::Twist(p), Kinematics::Twist(q)) => exprs(p, q),
                (Kinematics::Constraints(p), Kinematics::Constraints(q)) => {
                    p.noise == q.noise
                        && p.rows.len() == q.rows.len()
                        && p.rows
                            .iter()
                            .zip(&q.rows)
                            .all(|(r, s)| r.0 == s.0 && exprs(&r.1, &s.1))
                }
                _ => false,
            },
        ),
        (
            "observations",
            a.observations.len() == b.observations.len()
                && a.observations
                    .iter()
                    .zip(&b.observations)
                    .all(|(p, q)| p.decl == q.decl && exprs(&p.exprs, &q.exprs)),
        ),
        (
            "inverse",
            match (&a.inverse, &b.inverse) {
                (Some(p), Some(q)) => exprs(&p.0, &q.0),
                (None, None) => true,
                _ => false,
            },
        ),
        ("effects", a.effects == b.effects),
    ];
    match checks.iter().find(|c| !c.1) {
        Some((what, _)) => Err(format!("the {what} differ")),
        None => Ok(()),
    }
}

/// Declarations compared through their serialised form (they are plain data).
fn same_json<T: serde::Serialize>(a: &T, b: &T) -> bool {
    serde_json::to_string(a).unwrap() == serde_json::to_string(b).unwrap()
}

/// Every specs' model with every effect that applies, and with every pair
/// of them: the typed model is the model its rendered spec text parses to.
/// The text is what add-effect writes and what a derivation reads, so a
/// change the renderer missed (or wrote differently) would derive another
/// model than the one the analysis reasons about.
#[test]
fn the_typed_model_is_the_model_its_spec_text_says() {
    let cat = catalogue(&[]).unwrap();
    let dir = |d: &str| Path::new(env!("CARGO_MANIFEST_DIR")).join(d);
    let mut specs: Vec<PathBuf> = ["../spec", "../tests/user_specs"]
        .iter()
        .flat_map(|d| {
            std::fs::read_dir(dir(d))
                .unwrap()
                .flatten()
                .map(|e| e.path())
        })
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    specs.sort();
    let mut checked = 0;
    for path in &specs {
        let Ok(base) = Model::load(path) else {
            continue;
        };
        let mut models = vec![(String::new(), base.clone())];
        for first in &cat {
            let Ok(one) = first.added_to(&base) else {
                continue;
            };
            for second in &cat {
                if let Ok(two) = second.added_to(&one) {
                    models.push((format!("{} + {}", first.name, second.name), two));
                }
            }
            models.push((first.name.clone(), one));
        }
        for (chain, m) in &models {
            let parsed = Model::parse(path, &m.source)
                .unwrap_or_else(|e| panic!("{} with {chain}: {e}\n{}", path.display(), m.source));
            if let Err(why) = same_model(m, &parsed) {
                panic!("{} with {chain}: {why}\n{}", path.display(), m.source);
            }
            checked += 1;
        }
    }
    assert!(checked > 300, "only {checked} models checked");
}

/// An effect file is checked when it is read: a hole its patch cannot
/// fill, an expression that does not parse, a key a parameter does not
/// have and a nominal value outside its bounds are each refused with the
/// file's line, before any model meets them.
#[test]
fn a_bad_effect_file_is_refused_at_its_line_when_read() {
    let slip = include_str!("../../../spec/effects/lateral_slip.toml");
    // the line of `at` (the changed text itself, or a parameter's block)
    let refused_at = |from: &str, to: &str, at: &str| {
        assert!(slip.contains(from), "{from}");
        let text = slip.replacen(from, to, 1);
        let line = text.lines().position(|l| l.contains(at)).unwrap() + 1;
        let e = definition::parse_effect(Path::new("fx/slip.toml"), &text)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with(&format!("fx/slip.toml: line {line},")), "{e}");
        e
    };
    let refused = |from: &str, to: &str| refused_at(from, to, to);
    let e = refused("({vy}) + k_slip", "({vz}) + k_slip");
    assert!(
        e.contains("`{vz}` is not a hole of this patch") && e.contains("{vx}, {vy}, {omega}"),
        "{e}"
    );
    let e = refused("({vy}) + k_slip", "({vy}) + * k_slip");
    assert!(e.contains("unexpected `*`"), "{e}");
    let e = refused("unit = \"s\"", "unti = \"s\"");
    assert!(e.contains("unknown field `unti`"), "{e}");
    let e = refused_at("nominal = 0.0", "nominal = 2.0", "[[parameter]]");
    assert!(e.contains("nominal 2 is outside its bounds"), "{e}");
    assert!(definition::parse_effect(Path::new("fx/slip.toml"), slip).is_ok());
}
