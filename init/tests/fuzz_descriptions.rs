//! Hostile descriptions: thousands of mutations of the six test robots'
//! URDFs and controller files (bytes flipped, lines dropped or repeated,
//! numbers replaced by extremes, text cut short) never panic `init`; each
//! is a spec that reads back, or an error naming the file.
use kinegen_init::{from_text, Controller, Options};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use std::path::{Path, PathBuf};

fn robots() -> Vec<(String, Option<String>)> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../tests/robots");
    let mut out = Vec::new();
    for name in ["burger", "hauler", "sidestep", "racer", "forklift", "trio"] {
        let r = dir.join(name);
        let urdf = std::fs::read_to_string(r.join("robot.urdf")).unwrap();
        let ctl = std::fs::read_to_string(r.join("controllers.yaml")).ok();
        out.push((urdf, ctl));
    }
    out
}

const EXTREMES: [&str; 8] = [
    "0", "-0.0", "1e308", "-1e308", "NaN", "inf", "1e-320", "3.4.5",
];

fn mutate(text: &str, rng: &mut SmallRng) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    match rng.gen_range(0..5) {
        0 if !lines.is_empty() => {
            let i = rng.gen_range(0..lines.len());
            lines.remove(i);
        }
        1 if !lines.is_empty() => {
            let i = rng.gen_range(0..lines.len());
            let l = lines[i].clone();
            lines.insert(i, l);
        }
        2 => {
            // a number replaced by an extreme
            let i = rng.gen_range(0..lines.len().max(1));
            if let Some(l) = lines.get_mut(i) {
                if let Some(p) = l.find(|c: char| c.is_ascii_digit()) {
                    let end = l[p..]
                        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
                        .map_or(l.len(), |e| p + e);
                    l.replace_range(p..end, EXTREMES[rng.gen_range(0..EXTREMES.len())]);
                }
            }
        }
        3 => {
            let joined = lines.join("\n");
            let cut = rng.gen_range(0..joined.len().max(1));
            return joined.chars().take(cut).collect();
        }
        _ => {
            let mut b = lines.join("\n").into_bytes();
            for _ in 0..rng.gen_range(1..4) {
                if !b.is_empty() {
                    let i = rng.gen_range(0..b.len());
                    b[i] = rng.gen_range(b' '..=b'~');
                }
            }
            return String::from_utf8_lossy(&b).into_owned();
        }
    }
    lines.join("\n")
}

#[test]
fn mutated_descriptions_never_panic_and_errors_name_their_file() {
    let robots = robots();
    let mut rng = SmallRng::seed_from_u64(68);
    let (mut refused, mut written) = (0, 0);
    for k in 0..3000 {
        let (urdf, ctl) = &robots[k % robots.len()];
        let (u, c) = if rng.gen_bool(0.5) || ctl.is_none() {
            (mutate(urdf, &mut rng), ctl.clone())
        } else {
            (urdf.clone(), ctl.as_deref().map(|c| mutate(c, &mut rng)))
        };
        let result = std::panic::catch_unwind(|| {
            let controller = match &c {
                Some(text) => match Controller::parse(Path::new("controllers.yaml"), text) {
                    Ok(c) => Some(c),
                    Err(e) => return Err(e),
                },
                None => None,
            };
            from_text(
                Path::new("robot.urdf"),
                &u,
                controller.as_ref(),
                &Options::default(),
            )
        });
        match result {
            Err(_) => panic!("init panicked on case {k}:\n{u}\n---\n{c:?}"),
            Ok(Ok(made)) => {
                written += 1;
                assert!(
                    made.spec.contains("[[parameter]]") || made.spec.contains("[[input]]"),
                    "case {k}"
                );
            }
            Ok(Err(e)) => {
                refused += 1;
                let f = e.file.display().to_string();
                assert!(
                    f == "robot.urdf" || f == "controllers.yaml" || f == "--base-link",
                    "case {k}: {e}"
                );
            }
        }
    }
    assert!(
        refused > 300 && written > 300,
        "{refused} refused, {written} written"
    );
}
