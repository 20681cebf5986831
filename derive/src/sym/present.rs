//! Presentation of canonical forms: the expression a person would write.
//!
//! The canonical form ([`crate::sym::canonical`](mod@crate::sym::canonical))
//! keeps trigonometric polynomials in Fourier form (`sin(alpha)^2` is
//! `1/2 - cos(2*alpha)/2`), which is unique but not how equations are read.
//! [`try_present`] turns it back into the usual form:
//!
//! * a multiple of one angle (`cos(2*alpha)`, `sin(3*x/2)`) becomes powers of
//!   the sine and cosine of that angle, with `sin^2` reduced to `1 - cos^2`,
//!   after which a pair of terms `k*X*cos^2 - k*X` becomes `-k*X*sin^2`, so
//!   of `sin^2` and `1 - cos^2` the shorter is printed
//!   (`J0h + J2h*sin(alpha)^2`, not `J0h + J2h - J2h*cos(alpha)^2`);
//! * sums of angles (`cos(q2 + q3)`) stay whole;
//! * the numerator's rational content and common monomial factor are pulled
//!   out, with a sign that makes most terms positive;
//! * a parameter in the denominator that divides some numerator terms is
//!   cancelled in those terms and kept only where it does not divide
//!   (`-b1*theta' - Kg^2*km*kt*theta'/Rm`, not `-(Rm*b1*theta' + ...)/Rm`);
//! * a denominator factor that is a named expression (`D = det M`) is written
//!   as its name.
//!
//! The result is equal to the input as a function (a test checks it against
//! the canonical form), but it is not itself canonical.

use std::collections::BTreeMap;

use super::canonical::{factorize, flip_for_reading, Ctx};
use super::expr::{Expr, Func, Node};
use super::poly::{rdiv, rmul, rneg, Atom, CResult, CanonError, Mono, Poly, Rules};
use super::rational::Rational;

/// A name for a recurring subexpression, e.g. `D` for `det M`.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub struct Name {
    /// The symbol printed in its place, e.g. `Expr::sym("D")`.
    pub symbol: Expr,
    /// Its definition.
    pub definition: Expr,
}

/// Largest multiple of an angle written as powers of its sine and cosine.
const MAX_MULTIPLE: i128 = 8;

/// Converts Fourier-form polynomials into powers of sines and cosines.
struct Converter<'a> {
    fourier: &'a Rules,
    /// Root relations of the canonical form plus `sin(b)^2 = 1 - cos(b)^2`
    /// for every base angle `b` met.
    rules: Rules,
    /// `(sin b, cos b)` atoms of the base angles met.
    bases: Vec<(Atom, Atom)>,
    cache: super::fxhash::FxHashMap<Atom, Option<Poly>>,
}

impl<'a> Converter<'a> {
    fn new(fourier: &'a Rules) -> Converter<'a> {
        Converter {
            fourier,
            rules: fourier.without_trig(),
            bases: Vec::new(),
            cache: Default::default(),
        }
    }

    /// `sin(b)`, `cos(b)` atoms of a base angle, registering `sin^2 = 1 - cos^2`.
    fn base(&mut self, b: Expr) -> CResult<Option<(Poly, Poly)>> {
        let (s, c) = (b.sin(), b.cos());
        let s_ok = matches!(s.node(), Node::Func(Func::Sin, x) if *x == b);
        let c_ok = matches!(c.node(), Node::Func(Func::Cos, x) if *x == b);
        if !(s_ok && c_ok) {
            return Ok(None);
        }
        let cp = Poly::atom(Atom(c));
        if !self.bases.contains(&(Atom(s), Atom(c))) {
            let one_minus_c2 = Poly::constant(Rational::ONE).sub(&cp.mul(&cp, &self.rules)?)?;
            self.rules.insert(Atom(s), 2, one_minus_c2);
            self.bases.push((Atom(s), Atom(c)));
        }
        Ok(Some((Poly::atom(Atom(s)), cp)))
    }

    /// The replacement of a trigonometric atom of a multiple angle, if any.
    fn atom(&mut self, a: Atom) -> CResult<Option<Poly>> {
        if let Some(p) = self.cache.get(&a) {
            return Ok(p.clone());
        }
        let p = self.multiple(a)?;
        self.cache.insert(a, p.clone());
        Ok(p)
    }

    fn multiple(&mut self, a: Atom) -> CResult<Option<Poly>> {
        let Some((is_sin, angle)) = self.fourier.trig_angle(a) else {
            return Ok(None);
        };
        let [(m, k)] = angle.terms() else {
            return Ok(None);
        };
        let n = k.numer();
        if m.is_one() || !(2..=MAX_MULTIPLE).contains(&n) {
            return Ok(None);
        }
        let inv_d = Rational::new(1, k.denom()).ok_or(CanonError::Overflow)?;
        let Some((sb, cb)) = self.base(Expr::rational(inv_d) * m.to_expr())? else {
            return Ok(None);
        };
        // sin((j+1)b) = s_j cb + c_j sb, cos((j+1)b) = c_j cb - s_j sb
        let (mut sk, mut ck) = (sb.clone(), cb.clone());
        for _ in 1..n {
            let ns = sk.mul(&cb, &self.rules)?.add(&ck.mul(&sb, &self.rules)?)?;
            let nc = ck.mul(&cb, &self.rules)?.sub(&sk.mul(&sb, &self.rules)?)?;
            sk = ns;
            ck = nc;
        }
        Ok(Some(if is_sin { sk } else { ck }))
    }

    /// A Fourier-form polynomial in powers of sines and cosines, then the
    /// shorter of `sin^2` and `1 - cos^2` for each pair of terms.
    fn convert(&mut self, p: &Poly) -> CResult<Poly> {
        let mut terms: Vec<(Mono, Rational)> = Vec::with_capacity(p.len());
        for (m, c) in p.terms() {
            let mut t: Option<Poly> = None;
            let mut plain = Mono::one();
            for (a, e) in m.vars() {
                match self.atom(*a)? {
                    Some(q) => {
                        let qe = q.pow(*e, &self.rules)?;
                        t = Some(match t {
                            None => qe,
                            Some(t) => t.mul(&qe, &self.rules)?,
                        });
                    }
                    None => plain = plain.mul(&Mono::atom(*a, *e))?,
                }
            }
            match t {
                None => terms.push((plain, *c)),
                Some(t) => {
                    for (tm, tc) in t.terms() {
                        terms.push((tm.mul(&plain)?, super::poly::rmul(*tc, *c)?));
                    }
                }
            }
        }
        let acc = self.rules.collect(terms)?;
        self.pair_squares(&acc)
    }

    /// `k*X*cos(b)^(e) - k*X*cos(b)^(e-2)` -> `-k*X*cos(b)^(e-2)*sin(b)^2`.
    fn pair_squares(&self, p: &Poly) -> CResult<Poly> {
        let mut terms: BTreeMap<Mono, Rational> = p.terms().iter().cloned().collect();
        for &(s, c) in &self.bases {
            loop {
                let mut hit = None;
                for (m, k) in terms.iter().rev() {
                    let e = m.exp_of(c);
                    if e < 2 {
                        continue;
                    }
                    let partner = m.with_exp(c, e - 2);
                    if terms.get(&partner).copied() == Some(rneg(*k)?) {
                        hit = Some((m.clone(), *k, partner));
                        break;
                    }
                }
                let Some((m, k, partner)) = hit else { break };
                terms.remove(&m);
                terms.remove(&partner);
                let merged = partner.with_exp(s, partner.exp_of(s) + 2);
                let v = match terms.get(&merged) {
                    Some(old) => super::poly::radd(*old, rneg(k)?)?,
                    None => rneg(k)?,
                };
                if v.is_zero() {
                    terms.remove(&merged);
                } else {
                    terms.insert(merged, v);
                }
            }
        }
        Poly::from_terms(terms)
    }
}

/// The presentation of `e` (see the module docs); denominator factors equal to
/// a name's definition (up to a constant) are written as the name.
pub fn try_present(e: Expr, names: &[Name]) -> Result<Expr, CanonError> {
    try_present_within(e, names, super::poly::MAX_TERMS)
}

/// [`try_present`] with a term budget: `Err(CanonError::TooLarge)` as soon as
/// an intermediate polynomial has more than `max_terms` terms.
pub fn try_present_within(e: Expr, names: &[Name], max_terms: usize) -> Result<Expr, CanonError> {
    Canonicalizer::new(max_terms).try_present(e, names)
}

/// A canonical-form context reused across expressions: the conversions of
/// shared subexpressions and the products of trigonometric atoms are
/// memoised, so presenting the entries of `M`, `bias`, ... one after the
/// other costs little more than the largest of them.
pub struct Canonicalizer {
    ctx: Ctx,
}

impl Canonicalizer {
    /// A context whose computations stop with [`CanonError::TooLarge`] at an
    /// intermediate polynomial of more than `max_terms` terms.
    pub fn new(max_terms: usize) -> Canonicalizer {
        Canonicalizer {
            ctx: Ctx::new(max_terms),
        }
    }

    /// [`crate::sym::try_is_zero`] in this context.
    pub fn try_is_zero(&mut self, e: Expr) -> Result<bool, CanonError> {
        if e.is_zero() {
            return Ok(true);
        }
        Ok(self.ctx.convert(e)?.num.is_zero())
    }

    /// [`crate::sym::try_canonical`] in this context.
    pub fn try_canonical(&mut self, e: Expr) -> Result<Expr, CanonError> {
        let r = self.ctx.convert(e)?;
        Ok(self.ctx.to_expr(&r))
    }

    /// [`crate::sym::try_simplify`] in this context.
    pub fn try_simplify(&mut self, e: Expr) -> Result<Expr, CanonError> {
        self.try_present(e, &[])
    }

    /// [`try_present`] in this context.
    pub fn try_present(&mut self, e: Expr, names: &[Name]) -> Result<Expr, CanonError> {
        present_in(&mut self.ctx, e, names)
    }
}

fn present_in(ctx: &mut Ctx, e: Expr, names: &[Name]) -> Result<Expr, CanonError> {
    let r = ctx.convert(e)?;
    if r.num.is_zero() {
        return Ok(Expr::zero());
    }
    let named = named_factors(ctx, names)?;
    let mut conv = Converter::new(&ctx.rules);
    let mut coeff = Rational::ONE;
    let mut den_atoms: Vec<(Atom, u32)> = Vec::new();
    let mut den: Vec<Expr> = Vec::new();
    for (f, k) in &r.den {
        if let Some((c, sym)) = named
            .iter()
            .find(|(p, _, _)| p == f)
            .map(|(_, c, s)| (*c, *s))
        {
            // f = definition / c
            for _ in 0..*k {
                coeff = rmul(coeff, c)?;
            }
            den.push(sym.powi(-(*k as i64)));
            continue;
        }
        if let [(m, one)] = f.terms() {
            if one.is_one() && m.deg() == 1 && matches!(m.vars()[0].0 .0.node(), Node::Symbol(_)) {
                den_atoms.push((m.vars()[0].0, *k));
                continue;
            }
        }
        let pf = conv.convert(f)?;
        let c = pf.content()?;
        let mut prim = pf.scale(rdiv(Rational::ONE, c)?)?;
        for _ in 0..*k {
            coeff = rdiv(coeff, c)?;
        }
        if flip_for_reading(&prim) {
            prim = prim.neg()?;
            if k % 2 == 1 {
                coeff = rneg(coeff)?;
            }
        }
        den.push(prim.to_expr().powi(-(*k as i64)));
    }
    let pn = conv.convert(&r.num)?;
    let c = pn.content()?;
    let prim = pn.scale(rdiv(Rational::ONE, c)?)?;
    let m = prim.mono_gcd();
    let mut rest = prim.div_mono(&m);
    coeff = rmul(coeff, c)?;
    if flip_for_reading(&rest) {
        coeff = rneg(coeff)?;
        rest = rest.neg()?;
    }
    let shares = |t: &Mono| den_atoms.iter().any(|(a, _)| t.exp_of(*a) > 0);
    let body =
        if !den_atoms.is_empty() && rest.len() > 1 && rest.terms().iter().any(|(t, _)| shares(t)) {
            // cancel denominator parameters term by term
            Expr::add_all(rest.terms().iter().map(|(t, k)| {
                let mut t = t.clone();
                let mut fs = Vec::new();
                for (a, e) in &den_atoms {
                    let j = t.exp_of(*a).min(*e);
                    t = t.with_exp(*a, t.exp_of(*a) - j);
                    if *e > j {
                        fs.push(a.0.powi(-((*e - j) as i64)));
                    }
                }
                fs.push(Expr::rational(*k));
                fs.push(t.to_expr());
                Expr::mul_all(fs)
            }))
        } else {
            for (a, e) in &den_atoms {
                den.push(a.0.powi(-(*e as i64)));
            }
            rest.to_expr()
        };
    let mut fs = vec![Expr::rational(coeff), m.to_expr(), body];
    fs.extend(den);
    Ok(Expr::mul_all(fs))
}

/// Canonical primitive polynomials of the names' definitions (those that are
/// one polynomial factor), with the constant `c` such that
/// `definition = c * factor`.
fn named_factors(ctx: &mut Ctx, names: &[Name]) -> CResult<Vec<(Poly, Rational, Expr)>> {
    let mut out = Vec::new();
    for n in names {
        let r = ctx.convert(n.definition)?;
        if !r.den.is_empty() || r.num.is_zero() {
            continue;
        }
        let (c, fs) = factorize(&r.num)?;
        if let [(f, 1)] = fs.as_slice() {
            out.push((f.clone(), c, n.symbol));
        }
    }
    Ok(out)
}

/// [`try_present`], falling back to `e` unchanged if exact arithmetic fails.
pub fn present(e: Expr, names: &[Name]) -> Expr {
    try_present(e, names).unwrap_or(e)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sym::is_zero;

    #[test]
    fn shorter_square_and_whole_sums() {
        let a = Expr::sym("alpha");
        let (j0, j2) = (Expr::sym("J0h"), Expr::sym("J2h"));
        let m00 = j0 + j2 * a.sin().powi(2);
        assert_eq!(
            try_present(m00, &[]).unwrap().to_string(),
            "J0h + J2h*sin(alpha)^2"
        );
        let m01 = j0 + j2 - j2 * a.cos().powi(2);
        assert_eq!(
            try_present(m01, &[]).unwrap().to_string(),
            "J0h + J2h*sin(alpha)^2"
        );
        let (q2, q3) = (Expr::sym("q2"), Expr::sym("q3"));
        let e = q2.cos() * q3.cos() - q2.sin() * q3.sin();
        assert_eq!(try_present(e, &[]).unwrap().to_string(), "cos(q2 + q3)");
    }

    #[test]
    fn parameters_cancel_term_by_term_and_names() {
        let (rm, b1, k, td) = (
            Expr::sym("Rm"),
            Expr::sym("b1"),
            Expr::sym("K"),
            Expr::sym("th'"),
        );
        let e = -(rm * b1 * td + k * td) / rm;
        let p = try_present(e, &[]).unwrap();
        assert_eq!(p.to_string(), "-(b1 + K/Rm)*th'");
        assert!(is_zero(p - e));
        let a = Expr::sym("alpha");
        let d = Expr::sym("J") + Expr::sym("c") * a.cos().powi(2);
        let name = Name {
            symbol: Expr::sym("D"),
            definition: d,
        };
        let f = a.sin() / (2 * d);
        assert_eq!(
            try_present(f, &[name]).unwrap().to_string(),
            "sin(alpha)/(2*D)"
        );
    }
}
