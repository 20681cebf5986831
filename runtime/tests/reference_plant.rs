//! The hand-written reference plant reproduces the thesis' linear model
//! (Eq. 3-4) when given the Quanser manual's parameter choices.

use plantc_runtime::{PendulumParams, Plant, RotaryPendulumReference};

/// Printed A (rows 3 and 4) and B of the thesis.
const A3: [f64; 4] = [0.0, 81.4033, -45.8259, -0.9319];
const A4: [f64; 4] = [0.0, 122.0545, -44.0966, -1.3972];
const B: [f64; 2] = [83.4659, 80.3162];

fn jacobian(p: &RotaryPendulumReference) -> ([[f64; 4]; 4], [f64; 4]) {
    let h = 1e-6;
    let mut a = [[0.0; 4]; 4];
    let mut b = [0.0; 4];
    let mut fp = [0.0; 4];
    let mut fm = [0.0; 4];
    for j in 0..4 {
        let mut xp = [0.0; 4];
        let mut xm = [0.0; 4];
        xp[j] = h;
        xm[j] = -h;
        p.derivatives(&xp, &[0.0], &mut fp);
        p.derivatives(&xm, &[0.0], &mut fm);
        for i in 0..4 {
            a[i][j] = (fp[i] - fm[i]) / (2.0 * h);
        }
    }
    p.derivatives(&[0.0; 4], &[h], &mut fp);
    p.derivatives(&[0.0; 4], &[-h], &mut fm);
    for i in 0..4 {
        b[i] = (fp[i] - fm[i]) / (2.0 * h);
    }
    (a, b)
}

#[test]
fn manual_parameters_give_the_printed_linear_model() {
    let d = PendulumParams::default();
    let manual = PendulumParams {
        // The manual uses the table's arm inertia as the pivot inertia.
        j1: 9.98e-4 - d.m1 * d.l1 * d.l1,
        l2: 0.337 / 2.0,
        eta_m: 1.0,
        eta_g: 1.0,
        ..d
    };
    let (a, b) = jacobian(&RotaryPendulumReference::new(manual));
    let close = |x: f64, y: f64| (x - y).abs() <= 0.002 * y.abs() + 1e-9;
    for j in 0..4 {
        assert!(
            close(a[2][j], A3[j]),
            "A[2][{j}] = {} vs {}",
            a[2][j],
            A3[j]
        );
        assert!(
            close(a[3][j], A4[j]),
            "A[3][{j}] = {} vs {}",
            a[3][j],
            A4[j]
        );
    }
    assert!(close(b[2], B[0]) && close(b[3], B[1]), "{b:?}");
    assert_eq!(a[0][2], 1.0);
    assert_eq!(a[1][3], 1.0);
}

#[test]
fn wrong_lengths_give_nan_not_panic() {
    let p = RotaryPendulumReference::default();
    let mut dx = [0.0; 4];
    p.derivatives(&[0.0; 3], &[0.0], &mut dx);
    assert!(dx.iter().all(|v| v.is_nan()));
    p.derivatives(&[0.0; 4], &[], &mut dx);
    assert!(dx.iter().all(|v| v.is_nan()));
    let mut short = [0.0; 2];
    p.derivatives(&[0.0; 4], &[0.0], &mut short);
}

#[test]
fn observer_spec_linearizes_like_the_printed_model() {
    // ObserverSpec::from_smooth_plant uses the same central differences as
    // `jacobian` above, whose result is checked against the thesis' Eq. 3-4.
    let p = RotaryPendulumReference::default();
    let (a, b) = jacobian(&p);
    let spec = plantc_runtime::ObserverSpec::from_smooth_plant(&p).unwrap();
    for (i, row) in a.iter().enumerate() {
        assert_eq!(&spec.a[i * 4..(i + 1) * 4], row, "row {i} of A");
    }
    assert_eq!(spec.b, b, "B");
    assert_eq!(
        spec.accel_std,
        plantc_runtime::velocity_observer::DEFAULT_ACCEL_STD
    );
}
