//! Prints every bundled model's exact step, its state Jacobian and its twist on
//! fixed inputs (the inputs too), in whatever float type the generated crate was
//! built with: `kinegen-verify`'s f32 test builds this with the `f32` feature
//! and compares the lines with the f64 kernels.
//!
//! Line format: `model function case | x | u | w | p | dt | outputs`, values
//! as f64 text (an f32 widens exactly).
use kinegen_generated::Real;

// `Real` is f32 in the `f32` build, where the cast is not the identity
#[allow(clippy::unnecessary_cast)]
fn show(v: &[Real]) -> String {
    v.iter()
        .map(|x| format!("{:e}", *x as f64))
        .collect::<Vec<_>>()
        .join(" ")
}

macro_rules! probe {
    ($($m:ident),*) => {$({
        use kinegen_generated::$m as m;
        let p = m::Params::NOMINAL.to_array();
        // u = 0 takes the series branch; the others the closed form at
        // several turn rates; the last two turn by 0.06 and 0.2 rad in the
        // step, just past the f64 build's series switch (0.05), where the
        // closed form loses most to cancellation
        for (case, (scale, turn)) in [(0.0, None), (0.01, None), (1.0, None), (30.0, None), (3000.0, None), (30.0, Some(0.06)), (30.0, Some(0.2))].into_iter().enumerate() {
            let x: [Real; 3] = [0.3, -0.2, 0.7];
            let u = core::array::from_fn(|i| (scale * (1.0 - 0.61 * i as f64)) as Real);
            let w = core::array::from_fn(|i| (0.001 * i as f64) as Real);
            let omega = m::twist(&u, &p)[2] as f64;
            let dt: Real = match turn {
                Some(a) if omega != 0.0 => (a / omega.abs()) as Real,
                _ => 0.05,
            };
            let inputs = format!("| {} | {} | {} | {} | {:e} |", show(&x), show(&u), show(&w), show(&p), dt as f64);
            let step = m::step_exact(&x, &u, &w, &p, dt);
            println!("{} step_exact {case} {inputs} {}", stringify!($m), show(&step));
            let jx = m::step_exact_jac_x(&x, &u, &w, &p, dt);
            println!("{} step_exact_jac_x {case} {inputs} {}", stringify!($m), show(jx.as_flattened()));
            let ju = m::step_exact_jac_u(&x, &u, &w, &p, dt);
            println!("{} step_exact_jac_u {case} {inputs} {}", stringify!($m), show(ju.as_flattened()));
            println!("{} twist {case} {inputs} {}", stringify!($m), show(&m::twist(&u, &p)));
        }
    })*};
}

fn main() {
    kinegen_generated::for_each_model!(probe);
}
