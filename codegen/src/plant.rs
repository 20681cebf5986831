//! Emission of the plant functions: `PlantCoeffs`, `Plant` and the free
//! functions `dynamics`, `jacobian_x`, `jacobian_u`, `rk4_step`.
//!
//! All four are built in one value-numbered [`Graph`], so a parameter-only
//! subexpression is one coefficient shared by every function (and by the four
//! Runge-Kutta stages), computed once by `PlantCoeffs::new` when the
//! parameters are set ([`Plant::set_params`]); the free functions compute the
//! coefficients they need on every call.

use proc_macro2::TokenStream;
use quote::quote;

use plantc_derive::mechanics::{
    angle_coordinates, separable_mass, AngleCoordinates, Equations, SeparableMass,
};
use plantc_derive::model::Model;
use plantc_derive::sym::{diff, Expr, Rational, Symbol};

use crate::emit::idx;
use crate::ir::{Env, Graph, Level, V};
use crate::lower::ident;
use crate::Error;

/// Parameter inputs `p.<name>` of a graph, in model order.
pub(crate) fn param_inputs(g: &mut Graph, model: &Model, base: &TokenStream) -> Vec<V> {
    model
        .parameters
        .iter()
        .map(|p| {
            let f = ident(&p.name);
            g.input(quote!(#base.#f), Level::Param)
        })
        .collect()
}

/// An environment binding states to `xs`, inputs to `us`, parameters to
/// `ps` and derived quantities to their (parameter-only) definitions.
pub(crate) fn env(
    g: &mut Graph,
    model: &Model,
    xs: &[V],
    us: &[V],
    ps: &[V],
) -> Result<Env, Error> {
    let mut env = Env::default();
    for (s, v) in model.state_symbols().into_iter().zip(xs) {
        env.bind(s, *v);
    }
    for (s, v) in model.input_symbols().into_iter().zip(us) {
        env.bind(s, *v);
    }
    for (p, v) in model.parameters.iter().zip(ps) {
        env.bind(p.symbol, *v);
    }
    for d in &model.derived {
        let v = g.expr(&mut env, model.expand_derived(d.expr))?;
        env.bind(d.symbol, v);
    }
    Ok(env)
}

/// The coordinates the accelerations are computed in: the model's, or the
/// coordinates of the trigonometric arguments `theta = S q`
/// ([`plantc_derive::mechanics::angle_coordinates`]), where the mass matrix
/// and bias have far fewer terms (an n-link chain in relative angles).
pub(crate) enum Frame<'a> {
    /// `M(q) q'' = Q0 - bias + B u`.
    Model(&'a Equations),
    /// `M_theta theta'' = S^-T (Q0 + B u) - bias_theta`, `q'' = S^-1 theta''`.
    Angles(&'a Equations, &'a AngleCoordinates),
}

impl Frame<'_> {
    fn n(&self) -> usize {
        match self {
            Frame::Model(e) | Frame::Angles(e, _) => e.coords.len(),
        }
    }
}

/// `sum_j c_j v_j` for rational `c_j` (exact zeros skipped).
pub(crate) fn combination(g: &mut Graph, coeffs: &[Rational], vs: &[V]) -> V {
    let mut acc = g.konst(0.0);
    for (c, v) in coeffs.iter().zip(vs) {
        if c.is_zero() {
            continue;
        }
        let t = if c.is_one() {
            *v
        } else if *c == Rational::MINUS_ONE {
            g.neg(*v)
        } else {
            let k = g.konst(c.to_f64());
            g.mul(k, *v)
        };
        acc = g.add(acc, t);
    }
    acc
}

/// Bind `theta_k = (S q)_k` and `theta_k' = (S q')_k` in `env` (for the
/// angle frame); returns the values of `theta`.
fn bind_angles(g: &mut Graph, env: &mut Env, frame: &Frame, xs: &[V]) -> Vec<V> {
    let Frame::Angles(_, ac) = frame else {
        return Vec::new();
    };
    let n = frame.n();
    let mut theta = Vec::with_capacity(n);
    for k in 0..n {
        let t = combination(g, &ac.s[k], &xs[..n]);
        let td = combination(g, &ac.s[k], &xs[n..2 * n]);
        env.bind(ac.coords[k].q, t);
        env.bind(ac.coords[k].qd, td);
        theta.push(t);
    }
    theta
}

/// `M` (symmetric, from its lower triangle) and the right-hand side of the
/// frame, lowered in `env`.
fn mass_and_rhs(
    g: &mut Graph,
    env: &mut Env,
    frame: &Frame,
) -> Result<(Vec<Vec<V>>, Vec<V>), Error> {
    let n = frame.n();
    let zero = g.konst(0.0);
    let mass = match frame {
        Frame::Model(eqs) => &eqs.mass_matrix,
        Frame::Angles(_, ac) => &ac.equations.mass_matrix,
    };
    let mut m = vec![vec![zero; n]; n];
    for i in 0..n {
        for j in 0..=i {
            let v = g.expr(env, mass[i][j])?;
            m[i][j] = v;
            m[j][i] = v;
        }
    }
    let r = match frame {
        Frame::Model(eqs) => eqs
            .rhs()
            .iter()
            .map(|e| g.expr(env, *e))
            .collect::<Result<Vec<_>, _>>()?,
        Frame::Angles(eqs, ac) => {
            let forces = applied_forces(eqs);
            let fq = forces
                .iter()
                .map(|e| g.expr(env, *e))
                .collect::<Result<Vec<_>, _>>()?;
            let mut r = Vec::with_capacity(n);
            for k in 0..n {
                // (S^-T f)_k = sum_i S^-1[i][k] f_i
                let col: Vec<Rational> = (0..n).map(|i| ac.s_inv[i][k]).collect();
                let f = combination(g, &col, &fq);
                let b = g.expr(env, ac.equations.bias[k])?;
                r.push(g.sub(f, b));
            }
            r
        }
    };
    Ok((m, r))
}

/// `Q0 + B u` of each model coordinate.
fn applied_forces(eqs: &Equations) -> Vec<Expr> {
    (0..eqs.coords.len())
        .map(|i| {
            let bu: Expr = eqs
                .inputs
                .iter()
                .enumerate()
                .map(|(j, u)| eqs.input_matrix[i][j] * Expr::symbol(*u))
                .sum();
            eqs.forces[i] + bu
        })
        .collect()
}

/// Accelerations of the frame mapped to the model's `q''`.
fn to_model(g: &mut Graph, frame: &Frame, a: Vec<V>) -> Vec<V> {
    match frame {
        Frame::Model(_) => a,
        Frame::Angles(_, ac) => (0..a.len())
            .map(|i| combination(g, &ac.s_inv[i], &a))
            .collect(),
    }
}

#[allow(clippy::too_many_arguments)]
/// `x' = (q', q'')` at the state values `xs`. With `shift = (theta0, d)`
/// (a Runge-Kutta stage `xs = x0 + d`), `sin` and `cos` of a trigonometric
/// argument whose sine or cosine was needed at `x0` are formed by the
/// addition formulas from those at `x0` and `sin_cos_step` of its increment.
fn state_derivative(
    g: &mut Graph,
    model: &Model,
    frame: &Frame,
    xs: &[V],
    us: &[V],
    ps: &[V],
    shift: Option<(&[V], &[V])>,
) -> Result<(Vec<V>, Vec<V>), Error> {
    let n = frame.n();
    let mut e = env(g, model, xs, us, ps)?;
    let theta = bind_angles(g, &mut e, frame, xs);
    if let Some((a0, d)) = shift {
        let (args, syms): (Vec<V>, Vec<Symbol>) = match frame {
            Frame::Model(_) => (
                a0[..n].to_vec(),
                model.state_symbols().into_iter().take(n).collect(),
            ),
            Frame::Angles(_, ac) => (a0.to_vec(), ac.coords.iter().map(|c| c.q).collect()),
        };
        let incr: Vec<V> = match frame {
            Frame::Model(_) => d[..n].to_vec(),
            Frame::Angles(_, ac) => (0..n).map(|k| combination(g, &ac.s[k], &d[..n])).collect(),
        };
        for i in 0..n {
            if g.has_trig(args[i]) {
                let (s, c) = g.sin_cos_shifted(args[i], incr[i]);
                let q = Expr::symbol(syms[i]);
                e.preset(q.sin(), s);
                e.preset(q.cos(), c);
            }
        }
    }
    let (m, r) = mass_and_rhs(g, &mut e, frame)?;
    let a = g.solve_sym(&m, &[r]).remove(0);
    let a = to_model(g, frame, a);
    let mut out: Vec<V> = xs[n..].to_vec();
    out.extend(a);
    let args = match frame {
        Frame::Model(_) => xs[..n].to_vec(),
        Frame::Angles(..) => theta,
    };
    Ok((out, args))
}

/// `d e / d x_j` for the state variable `j` (`q_j` or `q_j'`), through the
/// frame's coordinates: `sum_k S[k][j] de/dtheta_k + de/dq_j`.
fn state_diff(frame: &Frame, model: &Model, e: Expr, j: usize) -> Expr {
    let state = model.state_symbols();
    let direct = diff(e, state[j]);
    match frame {
        Frame::Model(_) => direct,
        Frame::Angles(_, ac) => {
            let n = frame.n();
            let (col, vel) = (j % n, j >= n);
            let mut terms = vec![direct];
            for k in 0..n {
                let c = ac.s[k][col];
                if c.is_zero() {
                    continue;
                }
                let t = if vel { ac.coords[k].qd } else { ac.coords[k].q };
                let d = diff(e, t);
                if !d.is_zero() {
                    terms.push(Expr::rational(c) * d);
                }
            }
            Expr::add_all(terms)
        }
    }
}

/// Fewest coordinates for which the forward dynamics are generated as the
/// separable recursion ([`crate::recursive`]) when the mass matrix has that
/// structure, instead of the closed form (`M` formed, LDL^T unrolled, the
/// Jacobians by symbolic derivatives, the four Runge-Kutta stages in one
/// graph). Measured on the n-link chain (`bench/chain_scaling.sh` with
/// `PLANTC_DYNAMICS_FORM=closed|recursive`, CPU ns per `Plant::dynamics`
/// call, two runs): closed 197/195 ns against recursive 228/212 at n = 8,
/// 234 against 290 at n = 9, 376/293 against 279/281 at n = 10, 527
/// against 367 at n = 12. The value is the smallest n at which the
/// recursion was faster in both runs (beyond it the closed form's `n^3/6`
/// LDL^T only loses more, and its code grows as `n^3`).
pub const RECURSIVE_MIN_COORDINATES: usize = 10;

/// The bodies of the plant functions and the coefficients they read.
struct PlantBodies {
    nk: proc_macro2::Literal,
    p_unused: bool,
    cstmts: Vec<TokenStream>,
    cvals: Vec<TokenStream>,
    dynamics: TokenStream,
    jacobian_x: TokenStream,
    jacobian_u: TokenStream,
    rk4: TokenStream,
}

/// Whether a function's statements or outputs mention `name` (tokens).
fn uses(f: &crate::ir::Function, name: &str) -> bool {
    f.stmts
        .iter()
        .chain(&f.inner)
        .chain(&f.outputs)
        .any(|t| format!(" {t}").contains(name))
}

/// `let _ = u;` / `let _ = k;` for a function that does not read them.
fn silence(f: &crate::ir::Function) -> TokenStream {
    let mut t = TokenStream::new();
    if !uses(f, " u [") {
        t.extend(quote!(let _ = u;));
    }
    if !uses(f, " k . 0") {
        t.extend(quote!(let _ = k;));
    }
    t
}

/// The generated plant items.
pub(crate) fn plant_items(model: &Model, eqs: &Equations) -> Result<TokenStream, Error> {
    let n = eqs.coords.len();
    let computed;
    let ac: Option<&AngleCoordinates> = match &eqs.angles {
        Some(ac) => Some(ac),
        None => {
            computed = angle_coordinates(model).map_err(Error::Mechanics)?;
            computed.as_ref()
        }
    };
    // `PLANTC_DYNAMICS_FORM=closed|recursive` overrides the size rule: a
    // benchmark knob (bench/chain_scaling.sh measures the rule with it),
    // not an option of the product
    let recursive = match std::env::var("PLANTC_DYNAMICS_FORM").as_deref() {
        Ok("closed") => false,
        Ok("recursive") => true,
        _ => n >= RECURSIVE_MIN_COORDINATES,
    };
    let separable = match ac {
        Some(ac) if recursive => separable_mass(ac).map(|sm| (ac, sm)),
        _ => None,
    };
    let bodies = match &separable {
        Some((ac, sm)) => recursive_bodies(model, eqs, ac, sm)?,
        None => closed_form_bodies(model, eqs, ac)?,
    };
    Ok(plant_tokens(bodies))
}

/// The plant functions by the separable recursion: `dynamics` unrolled
/// (`O(n)`), the Jacobians as its forward-mode derivative in a loop over the
/// directions, `rk4_step` calling `dynamics` four times.
fn recursive_bodies(
    model: &Model,
    eqs: &Equations,
    ac: &AngleCoordinates,
    sm: &SeparableMass,
) -> Result<PlantBodies, Error> {
    let n = eqs.coords.len();
    let nx = 2 * n;
    let nu = eqs.inputs.len();
    let mut g = Graph::new();
    let xs: Vec<V> = (0..nx)
        .map(|i| {
            let i = idx(i);
            g.input(quote!(x[#i]), Level::Call)
        })
        .collect();
    let us: Vec<V> = (0..nu)
        .map(|i| {
            let i = idx(i);
            g.input(quote!(u[#i]), Level::Call)
        })
        .collect();
    let ps = param_inputs(&mut g, model, &quote!(p));
    let dyn_out = crate::recursive::separable_dynamics(&mut g, model, eqs, ac, sm, &xs, &us, &ps)?;
    let seeds = |g: &mut Graph, vs: &[V]| -> std::collections::HashMap<V, V> {
        vs.iter()
            .enumerate()
            .map(|(i, v)| {
                let i = idx(i);
                (*v, g.input(quote!(e[#i]), Level::Dir))
            })
            .collect()
    };
    let sx = seeds(&mut g, &xs);
    let jx = g.tangent(&dyn_out, &sx)?;
    let su = seeds(&mut g, &us);
    let ju = g.tangent(&dyn_out, &su)?;
    let mut roots = dyn_out.clone();
    roots.extend(&jx);
    roots.extend(&ju);
    let plan = g.plan(&roots)?;
    let kref = quote!(k.0);
    let fd = g.function(&dyn_out, &plan, &kref)?;
    let fjx = g.function(&jx, &plan, &kref)?;
    let fju = g.function(&ju, &plan, &kref)?;
    let looped = |f: &crate::ir::Function, cols: TokenStream| {
        let s = silence(f);
        let (stmts, inner, outs) = (&f.stmts, &f.inner, &f.outputs);
        quote! {
            let _ = x;
            #s
            #(#stmts)*
            let mut jac = [[0.0; #cols]; N_STATES];
            let mut j = 0;
            while j < #cols {
                let mut e = [0.0; #cols];
                e[j] = 1.0;
                #(#inner)*
                let col: [f64; N_STATES] = [#(#outs),*];
                let mut i = 0;
                while i < N_STATES {
                    jac[i][j] = col[i];
                    i += 1;
                }
                j += 1;
            }
            jac
        }
    };
    let sd = silence(&fd);
    let (ds, dout) = (&fd.stmts, &fd.outputs);
    Ok(PlantBodies {
        nk: idx(plan.len()),
        p_unused: plan.stmts.is_empty() && plan.values.is_empty(),
        cstmts: plan.stmts,
        cvals: plan.values,
        dynamics: quote! {
            #sd
            #(#ds)*
            [#(#dout),*]
        },
        jacobian_x: looped(&fjx, quote!(N_STATES)),
        jacobian_u: looped(&fju, quote!(N_INPUTS)),
        rk4: quote! {
            let k1 = dynamics_k(x, u, k);
            let mut y = [0.0; N_STATES];
            let mut i = 0;
            while i < N_STATES { y[i] = x[i] + 0.5 * h * k1[i]; i += 1; }
            let k2 = dynamics_k(&y, u, k);
            let mut i = 0;
            while i < N_STATES { y[i] = x[i] + 0.5 * h * k2[i]; i += 1; }
            let k3 = dynamics_k(&y, u, k);
            let mut i = 0;
            while i < N_STATES { y[i] = x[i] + h * k3[i]; i += 1; }
            let k4 = dynamics_k(&y, u, k);
            let mut out = [0.0; N_STATES];
            let mut i = 0;
            while i < N_STATES {
                out[i] = x[i] + h / 6.0 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]);
                i += 1;
            }
            out
        },
    })
}

/// The plant functions in closed form: `M` and `r` formed and solved
/// (Cramer up to three coordinates, LDL^T beyond), the Jacobians from
/// symbolic derivatives, the four Runge-Kutta stages in one graph.
fn closed_form_bodies(
    model: &Model,
    eqs: &Equations,
    ac: Option<&AngleCoordinates>,
) -> Result<PlantBodies, Error> {
    let n = eqs.coords.len();
    let nx = 2 * n;
    let nu = eqs.inputs.len();
    let frame = match ac {
        Some(ac) => Frame::Angles(eqs, ac),
        None => Frame::Model(eqs),
    };
    let (mass_f, rhs_f): (Vec<Vec<Expr>>, Vec<Expr>) = match &frame {
        Frame::Model(eqs) => (eqs.mass_matrix.clone(), eqs.rhs()),
        Frame::Angles(eqs, ac) => {
            let forces = applied_forces(eqs);
            let rhs = (0..n)
                .map(|k| {
                    let f: Expr = (0..n)
                        .map(|i| Expr::rational(ac.s_inv[i][k]) * forces[i])
                        .sum();
                    f - ac.equations.bias[k]
                })
                .collect();
            (ac.equations.mass_matrix.clone(), rhs)
        }
    };

    let mut g = Graph::new();
    let xs: Vec<V> = (0..nx)
        .map(|i| {
            let i = idx(i);
            g.input(quote!(x[#i]), Level::Call)
        })
        .collect();
    let us: Vec<V> = (0..nu)
        .map(|i| {
            let i = idx(i);
            g.input(quote!(u[#i]), Level::Call)
        })
        .collect();
    let ps = param_inputs(&mut g, model, &quote!(p));

    // dynamics
    let (dyn_out, args0) = state_derivative(&mut g, model, &frame, &xs, &us, &ps, None)?;

    // Jacobians: da/dx_k = M^-1 (dr/dx_k - dM/dx_k a), da/du_k = M^-1 dr/du_k
    // (a, M, r in the frame's coordinates, then mapped to q'')
    let mut e = env(&mut g, model, &xs, &us, &ps)?;
    bind_angles(&mut g, &mut e, &frame, &xs);
    let (m, _) = mass_and_rhs(&mut g, &mut e, &frame)?;
    let a_frame: Vec<V> = match &frame {
        Frame::Model(_) => dyn_out[n..].to_vec(),
        Frame::Angles(..) => {
            let (m2, r2) = mass_and_rhs(&mut g, &mut e, &frame)?;
            g.solve_sym(&m2, &[r2]).remove(0)
        }
    };
    let mut cols = Vec::new();
    for j in 0..nx {
        let mut col = Vec::new();
        for i in 0..n {
            let mut c = g.expr(&mut e, state_diff(&frame, model, rhs_f[i], j))?;
            for (k, ak) in a_frame.iter().enumerate() {
                let dm = g.expr(&mut e, state_diff(&frame, model, mass_f[i][k], j))?;
                let t = g.mul(dm, *ak);
                c = g.sub(c, t);
            }
            col.push(c);
        }
        cols.push(col);
    }
    let da: Vec<Vec<V>> = g
        .solve_sym(&m, &cols)
        .into_iter()
        .map(|c| to_model(&mut g, &frame, c))
        .collect();
    let (zero, one) = (g.konst(0.0), g.konst(1.0));
    let mut jx = Vec::new(); // row-major
    for r in 0..nx {
        for k in 0..nx {
            jx.push(if r < n {
                if k == n + r {
                    one
                } else {
                    zero
                }
            } else {
                da[k][r - n]
            });
        }
    }
    let mut ucols = Vec::new();
    for s in &eqs.inputs {
        let col = (0..n)
            .map(|i| g.expr(&mut e, diff(rhs_f[i], *s)))
            .collect::<Result<Vec<_>, _>>()?;
        ucols.push(col);
    }
    let db: Vec<Vec<V>> = g
        .solve_sym(&m, &ucols)
        .into_iter()
        .map(|c| to_model(&mut g, &frame, c))
        .collect();
    let mut ju = Vec::new();
    for r in 0..nx {
        for k in 0..nu {
            ju.push(if r < n { zero } else { db[k][r - n] });
        }
    }

    // RK4 with u held: the stages share every coefficient
    let h = g.input(quote!(h), Level::Call);
    let half = g.konst(0.5);
    let hh = g.mul(half, h);
    let six = g.konst(6.0);
    let h6 = g.div(h, six);
    let two = g.konst(2.0);
    let k1 = dyn_out.clone();
    // stage increments d = w k and states x + d
    let stage = |g: &mut Graph, k: &[V], w: V| -> (Vec<V>, Vec<V>) {
        let d: Vec<V> = k.iter().map(|k| g.mul(w, *k)).collect();
        let y = xs.iter().zip(&d).map(|(x, d)| g.add(*x, *d)).collect();
        (y, d)
    };
    let (y2, d2) = stage(&mut g, &k1, hh);
    let (k2, _) = state_derivative(&mut g, model, &frame, &y2, &us, &ps, Some((&args0, &d2)))?;
    let (y3, d3) = stage(&mut g, &k2, hh);
    let (k3, _) = state_derivative(&mut g, model, &frame, &y3, &us, &ps, Some((&args0, &d3)))?;
    let (y4, d4) = stage(&mut g, &k3, h);
    let (k4, _) = state_derivative(&mut g, model, &frame, &y4, &us, &ps, Some((&args0, &d4)))?;
    let mut rk = Vec::new();
    for i in 0..nx {
        let s23 = g.add(k2[i], k3[i]);
        let s23 = g.mul(two, s23);
        let s = g.add(k1[i], s23);
        let s = g.add(s, k4[i]);
        let t = g.mul(h6, s);
        rk.push(g.add(xs[i], t));
    }

    let mut roots = dyn_out.clone();
    roots.extend(&jx);
    roots.extend(&ju);
    roots.extend(&rk);
    let plan = g.plan(&roots)?;
    let kref = quote!(k.0);
    let fd = g.function(&dyn_out, &plan, &kref)?;
    let fjx = g.function(&jx, &plan, &kref)?;
    let fju = g.function(&ju, &plan, &kref)?;
    let frk = g.function(&rk, &plan, &kref)?;

    let (ds, dout) = (&fd.stmts, &fd.outputs);
    let (jxs, jxo) = (&fjx.stmts, rows(&fjx.outputs, nx));
    let (jus, juo) = (&fju.stmts, rows(&fju.outputs, nu));
    let (rks, rko) = (&frk.stmts, &frk.outputs);
    let (sd, sjx, sju, srk) = (silence(&fd), silence(&fjx), silence(&fju), silence(&frk));
    let rk_x = if uses(&frk, " x [") {
        quote!()
    } else {
        quote!(let _ = x;)
    };
    Ok(PlantBodies {
        nk: idx(plan.len()),
        p_unused: plan.stmts.is_empty() && plan.values.is_empty(),
        cstmts: plan.stmts,
        cvals: plan.values,
        dynamics: quote! {
            #sd
            #(#ds)*
            [#(#dout),*]
        },
        jacobian_x: quote! {
            #sjx
            #(#jxs)*
            [#(#jxo),*]
        },
        jacobian_u: quote! {
            let _ = x;
            #sju
            #(#jus)*
            [#(#juo),*]
        },
        rk4: quote! {
            #rk_x
            #srk
            #(#rks)*
            [#(#rko),*]
        },
    })
}

/// The plant items around the function bodies.
fn plant_tokens(b: PlantBodies) -> TokenStream {
    let PlantBodies {
        nk,
        p_unused,
        cstmts,
        cvals,
        dynamics,
        jacobian_x,
        jacobian_u,
        rk4,
    } = b;
    let p_unused = if p_unused {
        quote!(let _ = p;)
    } else {
        quote!()
    };

    quote! {
        /// Parameter-only subexpressions of the plant functions (products of
        /// parameters, derived quantities, ...), computed once from [`Params`]
        /// so that [`Plant`]'s functions only do the work that depends on the
        /// state. Build with [`PlantCoeffs::new`]; recompute whenever the
        /// parameters change ([`Plant::set_params`] does).
        #[derive(Clone, Copy, Debug, PartialEq)]
        pub struct PlantCoeffs(pub [f64; #nk]);

        impl PlantCoeffs {
            /// The coefficients for the parameters `p`.
            #[inline(always)]
            pub fn new(p: &Params) -> PlantCoeffs {
                #p_unused
                #(#cstmts)*
                PlantCoeffs([#(#cvals),*])
            }
        }

        #[inline(always)]
        fn dynamics_k(x: &[f64; N_STATES], u: &[f64; N_INPUTS], k: &PlantCoeffs) -> [f64; N_STATES] {
            #dynamics
        }

        #[inline(always)]
        fn jacobian_x_k(x: &[f64; N_STATES], u: &[f64; N_INPUTS], k: &PlantCoeffs) -> [[f64; N_STATES]; N_STATES] {
            #jacobian_x
        }

        #[inline(always)]
        fn jacobian_u_k(x: &[f64; N_STATES], u: &[f64; N_INPUTS], k: &PlantCoeffs) -> [[f64; N_INPUTS]; N_STATES] {
            #jacobian_u
        }

        #[inline(always)]
        fn rk4_step_k(x: &[f64; N_STATES], u: &[f64; N_INPUTS], k: &PlantCoeffs, h: f64) -> [f64; N_STATES] {
            #rk4
        }

        /// The plant with its parameters and their precomputed coefficients
        /// ([`PlantCoeffs`]): the fast way to call the model repeatedly.
        /// The parameters are private so the coefficients cannot go stale;
        /// change them with [`Plant::set_params`].
        #[derive(Clone, Copy, Debug, PartialEq)]
        pub struct Plant {
            params: Params,
            k: PlantCoeffs,
        }

        impl Default for Plant {
            fn default() -> Self {
                Plant::new(Params::DEFAULT)
            }
        }

        impl Plant {
            /// The plant with parameters `params`.
            #[inline]
            pub fn new(params: Params) -> Plant {
                Plant { params, k: PlantCoeffs::new(&params) }
            }

            /// The parameters.
            #[inline]
            pub fn params(&self) -> &Params {
                &self.params
            }

            /// Change the parameters (recomputes the coefficients).
            #[inline]
            pub fn set_params(&mut self, params: Params) {
                *self = Plant::new(params);
            }

            /// The coefficients in use.
            #[inline]
            pub fn coeffs(&self) -> &PlantCoeffs {
                &self.k
            }

            /// State derivative `x' = f(x, u)` (see [`dynamics`]).
            #[inline]
            pub fn dynamics(&self, x: &[f64; N_STATES], u: &[f64; N_INPUTS]) -> [f64; N_STATES] {
                dynamics_k(x, u, &self.k)
            }

            /// `d f / d x` (see [`jacobian_x`]).
            #[inline]
            pub fn jacobian_x(&self, x: &[f64; N_STATES], u: &[f64; N_INPUTS]) -> [[f64; N_STATES]; N_STATES] {
                jacobian_x_k(x, u, &self.k)
            }

            /// `d f / d u` (see [`jacobian_u`]).
            #[inline]
            pub fn jacobian_u(&self, x: &[f64; N_STATES], u: &[f64; N_INPUTS]) -> [[f64; N_INPUTS]; N_STATES] {
                jacobian_u_k(x, u, &self.k)
            }

            /// One classical Runge-Kutta step of length `h` [s] with `u` held
            /// (see [`rk4_step`]).
            #[inline]
            pub fn rk4_step(&self, x: &[f64; N_STATES], u: &[f64; N_INPUTS], h: f64) -> [f64; N_STATES] {
                rk4_step_k(x, u, &self.k, h)
            }

            /// One classical Runge-Kutta step of length `h` [s] of the closed
            /// loop `x' = f(x, control(x))`: the controller is evaluated at
            /// every stage (a continuous-time controller, as in a
            /// continuous-time simulation), not held over the step. Returns
            /// the new state and the input at the start of the step.
            #[inline]
            pub fn closed_loop_rk4_step(
                &self,
                x: &[f64; N_STATES],
                h: f64,
                mut control: impl FnMut(&[f64; N_STATES]) -> [f64; N_INPUTS],
            ) -> ([f64; N_STATES], [f64; N_INPUTS]) {
                let u0 = control(x);
                let k1 = dynamics_k(x, &u0, &self.k);
                let mut y = [0.0; N_STATES];
                let mut i = 0;
                while i < N_STATES { y[i] = x[i] + 0.5 * h * k1[i]; i += 1; }
                let k2 = dynamics_k(&y, &control(&y), &self.k);
                let mut i = 0;
                while i < N_STATES { y[i] = x[i] + 0.5 * h * k2[i]; i += 1; }
                let k3 = dynamics_k(&y, &control(&y), &self.k);
                let mut i = 0;
                while i < N_STATES { y[i] = x[i] + h * k3[i]; i += 1; }
                let k4 = dynamics_k(&y, &control(&y), &self.k);
                let mut out = [0.0; N_STATES];
                let mut i = 0;
                while i < N_STATES {
                    out[i] = x[i] + h / 6.0 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]);
                    i += 1;
                }
                (out, u0)
            }
        }

        /// State derivative `x' = f(x, u)`: `M(q)` and `r = Q0 - bias + B u`
        /// evaluated with shared subexpressions and `M q'' = r` solved in
        /// closed form (never inverting `M` numerically by formula for more
        /// than three coordinates). Computes the parameter coefficients on
        /// every call; [`Plant::dynamics`] reuses them.
        #[inline]
        pub fn dynamics(x: &[f64; N_STATES], u: &[f64; N_INPUTS], p: &Params) -> [f64; N_STATES] {
            dynamics_k(x, u, &PlantCoeffs::new(p))
        }

        /// `A(x, u) = d f / d x` of the state equations `x' = f(x, u)`, from
        /// `da/dx = M^-1 (dr/dx - sum_k dM/dx_k a)` (symbolic `dr/dx`, `dM/dx`).
        #[inline]
        pub fn jacobian_x(x: &[f64; N_STATES], u: &[f64; N_INPUTS], p: &Params) -> [[f64; N_STATES]; N_STATES] {
            jacobian_x_k(x, u, &PlantCoeffs::new(p))
        }

        /// `B(x, u) = d f / d u` of the state equations (`M^-1 dr/du` below the
        /// kinematic rows).
        #[inline]
        pub fn jacobian_u(x: &[f64; N_STATES], u: &[f64; N_INPUTS], p: &Params) -> [[f64; N_INPUTS]; N_STATES] {
            jacobian_u_k(x, u, &PlantCoeffs::new(p))
        }

        /// One classical Runge-Kutta step of length `h` [s] with `u` held
        /// constant (the four stages inlined into one function; parameter
        /// coefficients computed once for the four). The sines and cosines
        /// of the coordinates at stages 2 to 4 come from those at `x` by the
        /// addition formulas with `math::sin_cos_step` of the stage increment.
        #[inline]
        pub fn rk4_step(x: &[f64; N_STATES], u: &[f64; N_INPUTS], p: &Params, h: f64) -> [f64; N_STATES] {
            rk4_step_k(x, u, &PlantCoeffs::new(p), h)
        }
    }
}

fn rows(flat: &[TokenStream], cols: usize) -> Vec<TokenStream> {
    flat.chunks(cols.max(1))
        .map(|r| quote!([#(#r),*]))
        .collect()
}
