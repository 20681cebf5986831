//! Accuracy of the Dormand-Prince integrator on problems with known solutions.

use plantc_derive::simulate::rk::{DormandPrince, RkOptions};

#[test]
fn harmonic_oscillator_to_1e_8() {
    // x'' = -w^2 x, x(0) = 1, x'(0) = 0: x = cos(w t).
    let w = 2.0 * std::f64::consts::PI * 1.7;
    let opts = RkOptions {
        rtol: 1e-11,
        atol: 1e-12,
        ..RkOptions::default()
    };
    let mut rk = DormandPrince::new(2, opts);
    let mut x = [1.0, 0.0];
    let mut f = |_t: f64, x: &[f64], dx: &mut [f64]| -> Result<(), ()> {
        dx[0] = x[1];
        dx[1] = -w * w * x[0];
        Ok(())
    };
    let mut t = 0.0;
    let mut worst: f64 = 0.0;
    for k in 1..=1000 {
        let t1 = k as f64 * 0.01;
        rk.advance(&mut f, t, t1, &mut x).unwrap();
        t = t1;
        worst = worst
            .max((x[0] - (w * t).cos()).abs())
            .max((x[1] / w + (w * t).sin()).abs());
    }
    assert_eq!(t, 10.0);
    eprintln!("oscillator: max error {worst:e}, {:?}", rk.stats);
    assert!(worst < 1e-8, "max error {worst:e}");
}

#[test]
fn default_tolerances_on_exponential_decay() {
    let mut rk = DormandPrince::new(1, RkOptions::default());
    let mut x = [1.0];
    rk.advance(
        &mut |_t: f64, x: &[f64], dx: &mut [f64]| -> Result<(), ()> {
            dx[0] = -3.0 * x[0];
            Ok(())
        },
        0.0,
        2.0,
        &mut x,
    )
    .unwrap();
    assert!((x[0] - (-6.0f64).exp()).abs() < 1e-9, "{}", x[0]);
}
