//! Canonical form: exact zero recognition for the expressions of mechanics.
//!
//! # The normal form
//!
//! An expression is converted to a rational function `N / (f1^k1 * ... * fr^kr)`
//! over *atoms*, with exact [`Rational`] coefficients:
//!
//! * **Atoms** are symbols, `sin(b)` and `cos(b)` for a canonical *base angle*
//!   `b`, roots `B^(1/q)` of canonical polynomials `B`, and opaque applications
//!   (`exp`, `ln`, `abs`, `sign`, `tanh`, `atan2`, symbolic or float exponents,
//!   float constants) whose arguments are canonicalised recursively, so
//!   `exp(a+b)` and `exp(b+a)` are the same atom.
//! * The numerator `N` is a sparse polynomial reduced modulo the side relations
//!   `sin(b)^2 = 1 - cos(b)^2` (so every monomial has degree at most 1 in each
//!   `sin`) and `(B^(1/q))^q = B`. These relations form a Gröbner basis (their
//!   leading monomials are pairwise coprime), so the reduced numerator of a
//!   polynomial is unique.
//! * The denominator is kept **factored**: a map from primitive polynomials
//!   (integer coprime coefficients, positive leading coefficient, no monomial
//!   factor; single atoms are their own factors) to multiplicities. Sums take the
//!   LCM of the factor maps instead of multiplying denominators, so a recurring
//!   mass-matrix determinant appears once. After every sum and product each
//!   denominator factor is cancelled against the numerator when exact
//!   multivariate division (modulo the side relations) says it divides.
//!
//! # Trigonometry
//!
//! `tan(u) = sin(u)/cos(u)`. The argument of `sin`/`cos` is canonicalised; if it
//! is a polynomial with at most [`MAX_ANGLE_TERMS`] terms it is split into terms
//! and expanded with the addition formulas; a term `(n/d)*m` (monomial `m`,
//! `|n| <= ` [`MAX_MULTIPLE`]) becomes the base angle `m/d` with multiplicity `n`,
//! expanded with the multiple-angle recurrences. So `sin(2x) = 2 sin(x) cos(x)`,
//! `cos(a-b) = cos(a)cos(b) + sin(a)sin(b)`, `sin(-x) = -sin(x)`. A rational
//! constant term `c` of an angle becomes the base angle `|c|` (atoms `sin(1)`,
//! `cos(1)`).
//!
//! # What is *not* recognised
//!
//! * Relations between different base angles of the same variable: `x/2` and `x`
//!   are independent bases, so `sin(x) - 2 sin(x/2) cos(x/2)` is not reduced to 0.
//!   Likewise `x/2 + x/3` is the base `x/6` (multiplicity 5) but `x/2` alone is
//!   the base `x/2`.
//! * Angles with more than [`MAX_ANGLE_TERMS`] terms or with a denominator are
//!   single bases (sign-normalised, so `sin(-u) = -sin(u)` still holds).
//! * `exp(a)*exp(b)` vs `exp(a+b)`, `ln` rules, `x^y*x^z` vs `x^(y+z)`,
//!   `sqrt(x)*sqrt(y)` vs `sqrt(x*y)`, `x^(1/2)*x^(1/3)` vs `x^(5/6)`, `abs`/`sign`
//!   identities, `sqrt(x^2)` vs `abs(x)`. A root of a rational function with a
//!   denominator is rewritten `(N/D)^(1/q) = (N*D*|D|^(q-2))^(1/q) / |D|` (exact
//!   wherever the left side is real), with `|f^k| = f^k` for even `k` and an
//!   opaque `abs(f)` atom for odd `k`, so its radicand is a polynomial.
//! * Numerator/denominator GCDs beyond "a denominator factor divides the
//!   numerator": two equal expressions may have different canonical forms if a
//!   common factor hides inside a product. [`is_zero`] and [`equivalent`] are
//!   nevertheless exact within the recognised algebra, because they test whether
//!   the numerator of a difference over a common denominator vanishes.
//!
//! Identities that hold only almost everywhere are used freely (`x/x = 1`,
//! `1/(1/x) = x`, `(sqrt(B))^2 = B`): the canonical form is a statement about
//! functions on the domain where both sides are defined.
//!
//! On overflow of the `i128` coefficients or excessive size the `try_*`
//! functions return a [`CanonError`]; the infallible wrappers fall back
//! gracefully (return the input unchanged, or `false`).

use std::collections::BTreeMap;

use super::fxhash::{FxHashMap as HashMap, FxHashSet as HashSet};
use std::rc::Rc;

use super::expr::{Expr, Func, Node};
use super::poly::{rdiv, Atom, CResult, CanonError, Poly, Rules};
use super::rational::Rational;

pub(super) type Den = BTreeMap<Poly, u32>;

/// A rational function with a factored denominator.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(super) struct RatFn {
    pub(super) num: Poly,
    pub(super) den: Den,
}

impl RatFn {
    fn poly(p: Poly) -> RatFn {
        RatFn {
            num: p,
            den: Den::new(),
        }
    }
    fn constant(c: Rational) -> RatFn {
        RatFn::poly(Poly::constant(c))
    }
}

/// Split a polynomial into `content * prod(factor^k)` with normalised factors.
pub(super) fn factorize(p: &Poly) -> CResult<(Rational, Vec<(Poly, u32)>)> {
    if p.is_zero() {
        return Err(CanonError::DivisionByZero);
    }
    let c = p.content()?;
    let prim = p.scale(rdiv(Rational::ONE, c)?)?;
    let m = prim.mono_gcd();
    let rest = prim.div_mono(&m);
    let mut out: Vec<(Poly, u32)> = m.vars().iter().map(|(a, e)| (Poly::atom(*a), *e)).collect();
    if rest.as_constant().is_none() {
        out.push((rest, 1));
    }
    Ok((c, out))
}

pub(super) struct Ctx {
    pub(super) rules: Rules,
    memo: HashMap<Expr, Rc<RatFn>>,
    visiting: HashSet<Expr>,
}

impl Ctx {
    pub(super) fn new(max_terms: usize) -> Ctx {
        Ctx {
            rules: Rules::with_budget(max_terms),
            memo: HashMap::default(),
            visiting: HashSet::default(),
        }
    }

    fn expand_den(&self, den: &Den) -> CResult<Poly> {
        let mut acc = Poly::constant(Rational::ONE);
        for (f, k) in den {
            acc = acc.mul(&f.pow(*k, &self.rules)?, &self.rules)?;
        }
        Ok(acc)
    }

    /// Cancel denominator factors that divide the numerator.
    fn cancel(&self, mut num: Poly, den: Den) -> CResult<RatFn> {
        if num.is_zero() {
            return Ok(RatFn::poly(num));
        }
        let mut out = Den::new();
        for (f, mut k) in den {
            while k > 0 {
                match num.div_exact(&f, &self.rules)? {
                    Some(q) => {
                        num = q;
                        k -= 1;
                    }
                    None => break,
                }
            }
            if k > 0 {
                out.insert(f, k);
            }
        }
        Ok(RatFn { num, den: out })
    }

    fn mul(&self, a: &RatFn, b: &RatFn) -> CResult<RatFn> {
        let num = a.num.mul(&b.num, &self.rules)?;
        if num.is_zero() {
            return Ok(RatFn::poly(num));
        }
        if b.den.is_empty() && a.den.is_empty() {
            return Ok(RatFn::poly(num));
        }
        let mut den = a.den.clone();
        for (f, k) in &b.den {
            *den.entry(f.clone()).or_insert(0) += k;
        }
        self.cancel(num, den)
    }

    /// Sum of several rational functions over the LCM of their denominators.
    fn sum(&self, items: &[Rc<RatFn>]) -> CResult<RatFn> {
        // Group by identical denominators first.
        let mut groups: BTreeMap<&Den, Poly> = BTreeMap::new();
        for it in items {
            let acc = groups.entry(&it.den).or_default();
            *acc = acc.add(&it.num)?;
        }
        if groups.len() == 1 {
            let (den, num) = groups.into_iter().next().expect("one group");
            if den.is_empty() {
                return Ok(RatFn::poly(num));
            }
            return self.cancel(num, den.clone());
        }
        let mut lcm = Den::new();
        for den in groups.keys() {
            for (f, k) in den.iter() {
                let e = lcm.entry(f.clone()).or_insert(0);
                *e = (*e).max(*k);
            }
        }
        let mut num = Poly::zero();
        for (den, n) in groups {
            if n.is_zero() {
                continue;
            }
            let mut cof = Den::new();
            for (f, k) in &lcm {
                let have = den.get(f).copied().unwrap_or(0);
                if *k > have {
                    cof.insert(f.clone(), k - have);
                }
            }
            let c = self.expand_den(&cof)?;
            num = num.add(&n.mul(&c, &self.rules)?)?;
        }
        self.cancel(num, lcm)
    }

    fn recip(&self, a: &RatFn) -> CResult<RatFn> {
        let (c, factors) = factorize(&a.num)?;
        let num = self.expand_den(&a.den)?.scale(rdiv(Rational::ONE, c)?)?;
        let mut den = Den::new();
        for (f, k) in factors {
            *den.entry(f).or_insert(0) += k;
        }
        self.cancel(num, den)
    }

    fn powi(&self, a: &RatFn, n: i128) -> CResult<RatFn> {
        let base = if n < 0 { self.recip(a)? } else { a.clone() };
        let n = u32::try_from(n.unsigned_abs()).map_err(|_| CanonError::Overflow)?;
        if n > 4096 {
            return Err(CanonError::TooLarge);
        }
        let num = base.num.pow(n, &self.rules)?;
        let den = base
            .den
            .into_iter()
            .map(|(f, k)| Ok((f, k.checked_mul(n).ok_or(CanonError::Overflow)?)))
            .collect::<CResult<Den>>()?;
        if den.is_empty() {
            Ok(RatFn::poly(num))
        } else {
            self.cancel(num, den)
        }
    }

    pub(super) fn to_expr(&self, r: &RatFn) -> Expr {
        let mut fs = vec![r.num.to_expr()];
        for (f, k) in &r.den {
            fs.push(f.to_expr().powi(-(*k as i64)));
        }
        Expr::mul_all(fs)
    }

    /// Negate if the numerator's leading coefficient is negative; returns the sign.
    fn sign_normalise(&self, r: &RatFn) -> CResult<(RatFn, i128)> {
        match r.num.leading() {
            Some((_, c)) if c.is_negative() => Ok((
                RatFn {
                    num: r.num.neg()?,
                    den: r.den.clone(),
                },
                -1,
            )),
            _ => Ok((r.clone(), 1)),
        }
    }

    fn atom(&self, e: Expr) -> RatFn {
        RatFn::poly(Poly::atom(Atom(e)))
    }

    pub(super) fn convert(&mut self, e: Expr) -> CResult<Rc<RatFn>> {
        if let Some(r) = self.memo.get(&e) {
            return Ok(r.clone());
        }
        if !self.visiting.insert(e) {
            // A rebuilt expression led back to itself: keep it opaque.
            return Ok(Rc::new(self.atom(e)));
        }
        let r = self.convert_node(e);
        self.visiting.remove(&e);
        let r = Rc::new(r?);
        self.memo.insert(e, r.clone());
        Ok(r)
    }

    fn canon_expr(&mut self, e: Expr) -> CResult<Expr> {
        let r = self.convert(e)?;
        Ok(self.to_expr(&r))
    }

    fn convert_node(&mut self, e: Expr) -> CResult<RatFn> {
        match e.node() {
            Node::Rational(r) => Ok(RatFn::constant(*r)),
            Node::Float(b) if b.value().is_finite() && b.value() < 0.0 => {
                // Sign-normalise inexact constants so that `-(2.5*x)` cancels `2.5*x`.
                let r = self.atom(Expr::float(-b.value()));
                Ok(RatFn {
                    num: r.num.neg()?,
                    den: r.den,
                })
            }
            Node::Float(_) | Node::Symbol(_) => Ok(self.atom(e)),
            Node::Add(ts) => {
                let items = ts
                    .iter()
                    .map(|t| self.convert(*t))
                    .collect::<CResult<Vec<_>>>()?;
                self.sum(&items)
            }
            Node::Mul(fs) => {
                let mut acc = RatFn::constant(Rational::ONE);
                let mut num_only = Poly::constant(Rational::ONE);
                let mut den = Den::new();
                // Multiply numerators, merge denominators, cancel once.
                for f in fs.iter() {
                    let r = self.convert(*f)?;
                    num_only = num_only.mul(&r.num, &self.rules)?;
                    for (p, k) in &r.den {
                        *den.entry(p.clone()).or_insert(0) += k;
                    }
                }
                acc.num = num_only;
                if den.is_empty() || acc.num.is_zero() {
                    return Ok(acc);
                }
                self.cancel(acc.num, den)
            }
            Node::Pow(b, x) => self.convert_pow(e, *b, *x),
            Node::Func(f, u) => self.convert_func(e, *f, *u),
            Node::Named(_, d) => Ok((*self.convert(*d)?).clone()),
            Node::Atan2(y, x) => {
                let cy = self.canon_expr(*y)?;
                let cx = self.canon_expr(*x)?;
                let built = Expr::atan2(cy, cx);
                self.rebuilt(built, matches!(built.node(), Node::Atan2(..)))
            }
        }
    }

    /// An opaque atom if `is_atom`, else convert the rebuilt expression.
    fn rebuilt(&mut self, built: Expr, is_atom: bool) -> CResult<RatFn> {
        if is_atom {
            Ok(self.atom(built))
        } else {
            Ok((*self.convert(built)?).clone())
        }
    }

    fn convert_pow(&mut self, _e: Expr, b: Expr, x: Expr) -> CResult<RatFn> {
        let cx = self.canon_expr(x)?;
        if let Some(r) = cx.as_rational() {
            let base = self.convert(b)?;
            if r.is_integer() {
                return self.powi(&base, r.numer());
            }
            let (p, q) = (r.numer(), r.denom());
            // `(N/D)^(1/q) = (N * D * |D|^(q-2))^(1/q) / |D|`: the root atom always
            // has a polynomial radicand (with its relation `atom^q = radicand`), so
            // the atom is the same however the rational function was written.
            let (radicand, inv_abs) = if base.den.is_empty() {
                (base.num.clone(), None)
            } else if let Some((abs_d, inv)) = self.abs_den(&base.den)? {
                let qm2 = u32::try_from(q - 2).map_err(|_| CanonError::TooLarge)?;
                let rad = base
                    .num
                    .mul(&self.expand_den(&base.den)?, &self.rules)?
                    .mul(&abs_d.pow(qm2, &self.rules)?, &self.rules)?;
                (rad, Some(inv))
            } else {
                let be = self.to_expr(&base);
                let built = be.pow(cx);
                return self.rebuilt(built, matches!(built.node(), Node::Pow(bb, _) if *bb == be));
            };
            let k = p.div_euclid(q);
            let rem = p.rem_euclid(q);
            let whole = self.powi(&base, k)?;
            let mut root = self.root(&radicand, q)?;
            if let Some(inv) = inv_abs {
                root = self.mul(
                    &root,
                    &RatFn {
                        num: Poly::constant(Rational::ONE),
                        den: inv,
                    },
                )?;
            }
            let part = self.powi(&root, rem)?;
            return self.mul(&whole, &part);
        }
        let cb = self.canon_expr(b)?;
        let built = cb.pow(cx);
        self.rebuilt(
            built,
            matches!(built.node(), Node::Pow(bb, xx) if *bb == cb && *xx == cx),
        )
    }

    /// `|D|` of a factored denominator, as a polynomial and as the factored
    /// denominator of `1/|D|`: even powers are their own absolute value, an odd
    /// power `f^k` becomes `f^(k-1) * abs(f)`. `None` if `abs(f)` does not convert
    /// to a polynomial with unit content.
    fn abs_den(&mut self, den: &Den) -> CResult<Option<(Poly, Den)>> {
        let mut abs_d = Poly::constant(Rational::ONE);
        let mut inv = Den::new();
        for (f, k) in den {
            let mut even = *k;
            if k % 2 == 1 {
                even -= 1;
                let a = self.convert(Expr::apply(Func::Abs, f.to_expr()))?;
                if !a.den.is_empty() {
                    return Ok(None);
                }
                let (c, fs) = factorize(&a.num)?;
                if c != Rational::ONE {
                    return Ok(None);
                }
                for (g, j) in fs {
                    *inv.entry(g).or_insert(0) += j;
                }
                abs_d = abs_d.mul(&a.num, &self.rules)?;
            }
            if even > 0 {
                *inv.entry(f.clone()).or_insert(0) += even;
                abs_d = abs_d.mul(&f.pow(even, &self.rules)?, &self.rules)?;
            }
        }
        Ok(Some((abs_d, inv)))
    }

    /// `B^(1/q)` as an atom with the relation `atom^q = B`.
    fn root(&mut self, b: &Poly, q: i128) -> CResult<RatFn> {
        let be = b.to_expr();
        let qe = Expr::rational(Rational::new(1, q).ok_or(CanonError::Overflow)?);
        let built = be.pow(qe);
        match built.node() {
            Node::Pow(bb, xx) if *bb == be && *xx == qe => {
                let qq = u32::try_from(q).map_err(|_| CanonError::Overflow)?;
                self.rules.insert(Atom(built), qq, b.clone());
                Ok(self.atom(built))
            }
            _ => Ok((*self.convert(built)?).clone()),
        }
    }

    fn convert_func(&mut self, e: Expr, f: Func, u: Expr) -> CResult<RatFn> {
        match f {
            Func::Sin | Func::Cos | Func::Tan => {
                let (s, c) = self.trig(u)?;
                match f {
                    Func::Sin => Ok(RatFn::poly(s)),
                    Func::Cos => Ok(RatFn::poly(c)),
                    _ => {
                        let inv = self.recip(&RatFn::poly(c))?;
                        self.mul(&RatFn::poly(s), &inv)
                    }
                }
            }
            _ => {
                let cu = self.convert(u)?;
                let odd = matches!(f, Func::Tanh | Func::Sign);
                let even = matches!(f, Func::Abs);
                let (cu, sign) = if odd || even {
                    self.sign_normalise(&cu)?
                } else {
                    ((*cu).clone(), 1)
                };
                let ce = self.to_expr(&cu);
                let built = Expr::apply(f, ce);
                let is_atom = matches!(built.node(), Node::Func(g, a) if *g == f && *a == ce);
                let r = if is_atom || built == e {
                    self.atom(built)
                } else {
                    (*self.convert(built)?).clone()
                };
                if odd && sign < 0 {
                    Ok(RatFn {
                        num: r.num.neg()?,
                        den: r.den,
                    })
                } else {
                    Ok(r)
                }
            }
        }
    }

    /// `(sin(u), cos(u))` as reduced polynomials: one trigonometric atom
    /// each, whose angle is the canonical polynomial of `u` (or an opaque
    /// atom for a rational function), sign-normalised.
    fn trig(&mut self, u: Expr) -> CResult<(Poly, Poly)> {
        let r = self.convert(u)?;
        if r.num.is_zero() {
            return Ok((Poly::zero(), Poly::constant(Rational::ONE)));
        }
        let angle = if r.den.is_empty() {
            r.num.clone()
        } else {
            // c * u with u = (N/c)/D primitive: an opaque angle atom, so that
            // the expression of any multiple converts back to the same atom
            let c = r.num.content()?;
            let u = RatFn {
                num: r.num.scale(rdiv(Rational::ONE, c)?)?,
                den: r.den.clone(),
            };
            let ua = Atom(self.to_expr(&u));
            self.rules.opaque_angle(ua);
            Poly::term(super::poly::Mono::atom(ua, 1), c)
        };
        Ok((
            self.rules.trig(true, &angle)?,
            self.rules.trig(false, &angle)?,
        ))
    }
}

pub(super) fn to_rat(e: Expr) -> CResult<(Ctx, Rc<RatFn>)> {
    to_rat_within(e, super::poly::MAX_TERMS)
}

pub(super) fn to_rat_within(e: Expr, max_terms: usize) -> CResult<(Ctx, Rc<RatFn>)> {
    let mut ctx = Ctx::new(max_terms);
    let r = ctx.convert(e)?;
    Ok((ctx, r))
}

/// The canonical form (see the module docs), or an error on overflow, an
/// identically zero denominator, or excessive size.
pub fn try_canonical(e: Expr) -> Result<Expr, CanonError> {
    let (ctx, r) = to_rat(e)?;
    Ok(ctx.to_expr(&r))
}

/// The canonical form: expanded numerator over a factored denominator. Falls back
/// to `e` itself if exact arithmetic fails.
pub fn canonical(e: Expr) -> Expr {
    try_canonical(e).unwrap_or(e)
}

/// Exact test for an identically zero expression (within the recognised
/// algebra; see the module docs).
pub fn try_is_zero(e: Expr) -> Result<bool, CanonError> {
    if e.is_zero() {
        return Ok(true);
    }
    let (_, r) = to_rat(e)?;
    Ok(r.num.is_zero())
}

/// [`try_is_zero`] with a term budget: `Err(CanonError::TooLarge)` as soon as
/// an intermediate polynomial has more than `max_terms` terms.
pub fn try_is_zero_within(e: Expr, max_terms: usize) -> Result<bool, CanonError> {
    if e.is_zero() {
        return Ok(true);
    }
    let (_, r) = to_rat_within(e, max_terms)?;
    Ok(r.num.is_zero())
}

/// [`try_simplify`] with a term budget (see [`try_is_zero_within`]).
pub fn try_simplify_within(e: Expr, max_terms: usize) -> Result<Expr, CanonError> {
    super::present::try_present_within(e, &[], max_terms)
}

/// True if `e` is identically zero. `false` when it is not, or when exact
/// arithmetic failed (never a false positive).
pub fn is_zero(e: Expr) -> bool {
    try_is_zero(e).unwrap_or(false)
}

/// True if `a - b` is identically zero.
pub fn equivalent(a: Expr, b: Expr) -> bool {
    a == b || is_zero(a - b)
}

/// Canonical form presented for reading (see [`crate::sym::present`]): sums
/// of angles kept whole, multiples of one angle as powers (the shorter of
/// `sin^2` and `1 - cos^2`), the numerator's content and common monomial factor
/// pulled out, parameters dividing only some terms kept with those terms, the
/// denominator as a product of factors.
pub fn try_simplify(e: Expr) -> Result<Expr, CanonError> {
    super::present::try_present(e, &[])
}

/// Presentation sign: mostly positive terms, ties broken by a positive
/// lowest-order term (`J0*J2 + J2^2 - c^2*cos(a)^2` rather than its negative).
pub(super) fn flip_for_reading(p: &Poly) -> bool {
    let neg = p.terms().iter().filter(|t| t.1.is_negative()).count();
    let pos = p.len() - neg;
    match neg.cmp(&pos) {
        std::cmp::Ordering::Greater => true,
        std::cmp::Ordering::Less => false,
        std::cmp::Ordering::Equal => p.terms().last().is_some_and(|t| t.1.is_negative()),
    }
}

/// [`try_simplify`], falling back to `e` on failure.
pub fn simplify(e: Expr) -> Expr {
    try_simplify(e).unwrap_or(e)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pythagoras_and_friends() {
        let x = Expr::sym("x");
        let y = Expr::sym("y");
        assert!(is_zero(x.sin().powi(2) + x.cos().powi(2) - 1));
        assert!(is_zero(x.tan() * x.cos() - x.sin()));
        assert!(is_zero((x.powi(2) - y.powi(2)) / (x - y) - (x + y)));
        assert!(is_zero((2 * x).sin() - 2 * x.sin() * x.cos()));
        assert!(is_zero(
            (x - y).cos() - x.cos() * y.cos() - x.sin() * y.sin()
        ));
        assert!(!is_zero(x.sin() - x.cos()));
        assert!(!is_zero(x.sin().powi(2) - 1));
        assert_eq!(canonical((x.powi(2) - y.powi(2)) / (x - y)), x + y);
    }

    #[test]
    fn roots_and_opaque() {
        let x = Expr::sym("x");
        let a = Expr::sym("a");
        let b = Expr::sym("b");
        let r = (x.powi(2) + 1).sqrt();
        assert!(is_zero(r * r - x.powi(2) - 1));
        assert!(is_zero((a + b).exp() - (b + a).exp()));
        assert!(is_zero((a * (a + b) / a - b).exp() - a.exp()));
    }
}
