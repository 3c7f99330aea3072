//! The generated crate built with its `f32` feature (every kernel in `f32`, for
//! a single-precision FPU) agrees with the f64 kernels to f32 accuracy: the
//! `probe` example of `examples/embed` is built with the feature in a target
//! directory of its own (features would otherwise unify with this f64 build)
//! and prints its inputs and outputs; the f64 kernels are evaluated here on the
//! same (f32-rounded) inputs. Cases include u = 0, which takes the series
//! branch of the removable singularity, whose switch point the f32 build moves.
use std::path::Path;
use std::process::Command;

fn parse(field: &str) -> Vec<f64> {
    field
        .split_whitespace()
        .map(|v| v.parse().unwrap())
        .collect()
}

fn arr<const N: usize>(v: &[f64]) -> [f64; N] {
    v.try_into()
        .expect("probe line has the kernel's argument length")
}

#[test]
fn the_f32_build_agrees_with_the_f64_kernels() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let target = root.join("target").join("f32-probe");
    let o = Command::new(env!("CARGO"))
        .current_dir(&root)
        .env("CARGO_TARGET_DIR", &target)
        .args([
            "run",
            "-q",
            "-p",
            "kinegen-embed-example",
            "--example",
            "probe",
            "--features",
            "kinegen-generated/f32",
        ])
        .output()
        .expect("cargo");
    assert!(
        o.status.success(),
        "building the f32 probe failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let text = String::from_utf8(o.stdout).unwrap();
    let mut checked = 0;
    let mut worst = (0.0f64, String::new());
    for line in text.lines() {
        let f: Vec<&str> = line.split('|').collect();
        let head: Vec<&str> = f[0].split_whitespace().collect();
        let (model, function) = (head[0], head[1]);
        let (x, u, w, p, dt, got) = (
            parse(f[1]),
            parse(f[2]),
            parse(f[3]),
            parse(f[4]),
            parse(f[5])[0],
            parse(f[6]),
        );
        macro_rules! want {
            ($($m:ident),*) => {
                match model {
                    $(stringify!($m) => {
                        use kinegen_generated::$m as m;
                        let p = arr(&p);
                        match function {
                            "step_exact" => m::step_exact(&arr(&x), &arr(&u), &arr(&w), &p, dt).to_vec(),
                            "step_exact_jac_x" => m::step_exact_jac_x(&arr(&x), &arr(&u), &arr(&w), &p, dt).as_flattened().to_vec(),
                            "step_exact_jac_u" => m::step_exact_jac_u(&arr(&x), &arr(&u), &arr(&w), &p, dt).as_flattened().to_vec(),
                            "twist" => m::twist(&arr(&u), &p).to_vec(),
                            other => panic!("unknown probe function {other}"),
                        }
                    })*
                    other => panic!("unknown probe model {other}"),
                }
            };
        }
        let want: Vec<f64> = kinegen_generated::for_each_model!(want);
        assert_eq!(want.len(), got.len(), "{line}");
        // relative to the output's own size (an entry near zero is compared
        // with the largest of its kernel's outputs)
        let scale = want.iter().fold(1e-3f64, |a, v| a.max(v.abs()));
        for (a, b) in want.iter().zip(&got) {
            let err = (a - b).abs() / scale;
            if err > worst.0 {
                worst = (err, format!("{model}::{function}: f64 {a:e}, f32 {b:e}"));
            }
        }
        checked += 1;
    }
    assert_eq!(
        checked,
        kinegen_generated::MODELS.len() * 7 * 4,
        "every model, case and kernel printed"
    );
    // f32 carries 24 bits (6e-8); the kernels chain a few dozen operations
    assert!(
        worst.0 < 2e-5,
        "f32 and f64 kernels differ by {:.1e} ({})",
        worst.0,
        worst.1
    );
    println!("worst relative difference {:.1e} ({})", worst.0, worst.1);
}
