//! The model file of an n-link planar pendulum: the scaling model of the
//! symbolic pipeline (`models/chain4.plant` and `models/chain10.plant` are
//! written by it; `bench/chain_scaling.sh` makes the others).
//!
//! Link `i` (uniform values, separate parameters `m_i`, `L_i`, `c_i`, `J_i`,
//! `b_i`) hangs from joint `i`; `q1` is measured from upright, `q_i` relative
//! to link `i - 1`, so link `i` points at `p_i = q1 + ... + q_i`. A torque
//! `tau` acts at joint 1; every joint has viscous friction. Outputs: `q1` and
//! `tip = q1 + ... + qn` (the last link's absolute angle). Each joint's
//! viscous friction `b_i` carries an `estimate` box (what a lab identifies
//! in the chain; the links are measured one by one).

use std::fmt::Write;

/// The `.plant` text of the `n`-link chain (`n >= 1`).
pub fn n_link_chain_source(n: usize) -> String {
    let n = n.max(1);
    let mut s = String::new();
    let sum =
        |f: &dyn Fn(usize) -> String, hi: usize| (1..=hi).map(f).collect::<Vec<_>>().join(" + ");
    let _ = writeln!(
        s,
        "# {n}-link planar pendulum: relative joint angles, torque at joint 1."
    );
    let _ = writeln!(
        s,
        "# Written by plantc_derive::model::n_link_chain_source({n})."
    );
    let _ = writeln!(s);
    let _ = writeln!(
        s,
        "model chain{n} \"{n}-link planar pendulum (relative joint angles, torque at joint 1)\""
    );
    let _ = writeln!(s);
    for i in 1..=n {
        let what = if i == 1 {
            "joint 1 angle from upright".to_string()
        } else {
            format!("joint {i} angle relative to link {}", i - 1)
        };
        let _ = writeln!(s, "coordinate q{i} : angle \"{what}\"");
    }
    let _ = writeln!(s);
    let _ = writeln!(s, "input tau [N*m] limits [-20, 20] \"torque at joint 1\"");
    let _ = writeln!(s);
    let _ = writeln!(s, "output q1");
    let _ = writeln!(
        s,
        "output tip = {} \"absolute angle of the last link\"",
        sum(&|k| format!("q{k}"), n)
    );
    let _ = writeln!(s);
    for line in [
        "# Identified (`estimate`): each joint's viscous friction, which depends on",
        "# the assembly (bearing preload, alignment) and shows only in the chain.",
        "# The links are alike and come apart: each is weighed, its centre of mass",
        "# found by balancing it and its inertia by swinging it alone as a compound",
        "# pendulum, and the joint to joint lengths are fixed by construction.",
        "# Boxes: up to 1e-2 N m s/rad, at which a link's swing about its joint",
        "# would die within one period (2*(J + m*c^2)/b = 0.27 s against 0.73 s),",
        "# which a joint on ball bearings does not do. g is not estimated.",
    ] {
        let _ = writeln!(s, "{line}");
    }
    for i in 1..=n {
        let _ = writeln!(s, "parameter m{i} = 0.1 [kg]          \"link {i} mass\"");
        let _ = writeln!(s, "parameter L{i} = 0.2 [m]           \"link {i} length\"");
        let _ = writeln!(
            s,
            "parameter c{i} = 0.1 [m]           \"joint {i} to the centre of mass of link {i}\""
        );
        let _ = writeln!(
            s,
            "parameter J{i} = 3.3e-4 [kg*m^2]   \"link {i} inertia about its centre of mass\""
        );
        let _ = writeln!(
            s,
            "parameter b{i} = 1e-4 [N*m*s/rad]  \"joint {i} viscous friction\" estimate [0, 1e-2]"
        );
    }
    let _ = writeln!(s, "parameter g = 9.81 [m/s^2]         \"gravity\"");
    let _ = writeln!(s);
    let _ = writeln!(s, "# absolute angles and rates of the links");
    for i in 1..=n {
        let _ = writeln!(s, "let p{i} = {}", sum(&|k| format!("q{k}"), i));
        let _ = writeln!(s, "let w{i} = {}", sum(&|k| format!("q{k}'"), i));
    }
    let _ = writeln!(s);
    let _ = writeln!(
        s,
        "# centre-of-mass velocity (vx, vy) and height y of each link"
    );
    for i in 1..=n {
        let part = |f: &str, last: bool, k: usize| {
            let len = if last {
                format!("c{k}")
            } else {
                format!("L{k}")
            };
            format!("{len}*{f}(p{k})")
        };
        let terms = |f: &str, rate: bool| {
            (1..=i)
                .map(|k| {
                    let t = part(f, k == i, k);
                    if rate {
                        format!("{t}*w{k}")
                    } else {
                        t
                    }
                })
                .collect::<Vec<_>>()
                .join(" + ")
        };
        let _ = writeln!(s, "let vx{i} = {}", terms("cos", true));
        let _ = writeln!(s, "let vy{i} = {}", terms("sin", true));
        let _ = writeln!(s, "let y{i} = {}", terms("cos", false));
    }
    let _ = writeln!(s);
    let _ = writeln!(
        s,
        "kinetic T = {}",
        (1..=n)
            .map(|i| format!("1/2*m{i}*(vx{i}^2 + vy{i}^2) + 1/2*J{i}*w{i}^2"))
            .collect::<Vec<_>>()
            .join(" + ")
    );
    let _ = writeln!(s, "potential V = {}", sum(&|i| format!("m{i}*g*y{i}"), n));
    let _ = writeln!(s);
    let _ = writeln!(s, "force q1 = tau + viscous_friction(b1)");
    for i in 2..=n {
        let _ = writeln!(s, "force q{i} = viscous_friction(b{i})");
    }
    let _ = writeln!(s);
    let ones = vec!["1"; 2 * n].join(", ");
    let _ = writeln!(s, "controller lqr_unit \"LQR with Q = I, R = 1\" {{");
    let _ = writeln!(s, "    lqr Q [{ones}] R [1]");
    let _ = writeln!(s, "}}");
    s
}
