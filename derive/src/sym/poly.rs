//! Sparse multivariate polynomials with exact rational coefficients over
//! "atoms" (symbols, `sin(u)`, `cos(u)`, roots and opaque function
//! applications), reduced modulo side relations such as `sin(u)^2 = 1 - cos(u)^2`.
//!
//! This is the arithmetic engine behind [`crate::sym::canonical`](mod@crate::sym::canonical). All
//! coefficient arithmetic is checked; overflow surfaces as
//! [`CanonError::Overflow`] instead of a panic.
//!
//! Ordering is structural ([`structural_cmp`] on the atoms), never by interning
//! id or hash order, so every result is deterministic.

use super::fxhash::{FxHashMap as HashMap, FxHashSet};
use std::cell::RefCell;
use std::cmp::Ordering;
use std::fmt;

use super::expr::{structural_cmp, Expr, Func, Node};
use super::rational::Rational;

/// Why an exact computation was abandoned.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash)]
pub enum CanonError {
    /// A rational coefficient or an exponent overflowed.
    Overflow,
    /// A denominator is identically zero.
    DivisionByZero,
    /// An intermediate polynomial exceeded the term limit.
    TooLarge,
}

impl fmt::Display for CanonError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            CanonError::Overflow => "exact arithmetic overflowed",
            CanonError::DivisionByZero => "division by an identically zero expression",
            CanonError::TooLarge => "intermediate polynomial too large",
        })
    }
}

impl std::error::Error for CanonError {}

/// Result alias for exact polynomial arithmetic.
pub type CResult<T> = Result<T, CanonError>;

/// Maximum number of terms of any intermediate polynomial.
pub const MAX_TERMS: usize = 200_000;

pub(crate) fn radd(a: Rational, b: Rational) -> CResult<Rational> {
    a.checked_add(b).ok_or(CanonError::Overflow)
}
pub(crate) fn rmul(a: Rational, b: Rational) -> CResult<Rational> {
    a.checked_mul(b).ok_or(CanonError::Overflow)
}
pub(crate) fn rdiv(a: Rational, b: Rational) -> CResult<Rational> {
    if b.is_zero() {
        return Err(CanonError::DivisionByZero);
    }
    a.checked_div(b).ok_or(CanonError::Overflow)
}
pub(crate) fn rneg(a: Rational) -> CResult<Rational> {
    a.checked_neg().ok_or(CanonError::Overflow)
}

fn igcd(mut a: i128, mut b: i128) -> i128 {
    a = a.abs();
    b = b.abs();
    while b != 0 {
        let t = a % b;
        a = b;
        b = t;
    }
    a
}

/// A polynomial variable: an interned expression ordered structurally.
#[derive(Copy, Clone, PartialEq, Eq, Hash, Debug)]
pub struct Atom(pub Expr);

impl PartialOrd for Atom {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Atom {
    fn cmp(&self, other: &Self) -> Ordering {
        if self.0 == other.0 {
            Ordering::Equal
        } else {
            structural_cmp(self.0, other.0)
        }
    }
}

/// A monomial: atoms in increasing structural order with positive exponents.
#[derive(Clone, PartialEq, Eq, Hash, Debug, Default)]
pub struct Mono {
    deg: u32,
    vars: Vec<(Atom, u32)>,
}

impl Mono {
    /// The empty monomial `1`.
    pub fn one() -> Mono {
        Mono::default()
    }

    /// `a^e`.
    pub fn atom(a: Atom, e: u32) -> Mono {
        if e == 0 {
            return Mono::one();
        }
        Mono {
            deg: e,
            vars: vec![(a, e)],
        }
    }

    /// Total degree.
    pub fn deg(&self) -> u32 {
        self.deg
    }

    /// The atoms with their exponents.
    pub fn vars(&self) -> &[(Atom, u32)] {
        &self.vars
    }

    /// True for the monomial `1`.
    pub fn is_one(&self) -> bool {
        self.vars.is_empty()
    }

    /// Exponent of `a`.
    pub fn exp_of(&self, a: Atom) -> u32 {
        match self.vars.binary_search_by(|(b, _)| b.cmp(&a)) {
            Ok(i) => self.vars[i].1,
            Err(_) => 0,
        }
    }

    /// The same monomial with the exponent of `a` set to `e`.
    pub fn with_exp(&self, a: Atom, e: u32) -> Mono {
        let mut vars = self.vars.clone();
        let mut deg = self.deg;
        match vars.binary_search_by(|(b, _)| b.cmp(&a)) {
            Ok(i) => {
                deg = deg - vars[i].1 + e;
                if e == 0 {
                    vars.remove(i);
                } else {
                    vars[i].1 = e;
                }
            }
            Err(i) => {
                if e > 0 {
                    deg += e;
                    vars.insert(i, (a, e));
                }
            }
        }
        Mono { deg, vars }
    }

    /// Product.
    pub fn mul(&self, o: &Mono) -> CResult<Mono> {
        if o.is_one() {
            return Ok(self.clone());
        }
        if self.is_one() {
            return Ok(o.clone());
        }
        let mut vars = Vec::with_capacity(self.vars.len() + o.vars.len());
        let (mut i, mut j) = (0, 0);
        while i < self.vars.len() && j < o.vars.len() {
            let (a, ea) = self.vars[i];
            let (b, eb) = o.vars[j];
            match a.cmp(&b) {
                Ordering::Less => {
                    vars.push((a, ea));
                    i += 1;
                }
                Ordering::Greater => {
                    vars.push((b, eb));
                    j += 1;
                }
                Ordering::Equal => {
                    vars.push((a, ea.checked_add(eb).ok_or(CanonError::Overflow)?));
                    i += 1;
                    j += 1;
                }
            }
        }
        vars.extend_from_slice(&self.vars[i..]);
        vars.extend_from_slice(&o.vars[j..]);
        Ok(Mono {
            deg: self.deg.checked_add(o.deg).ok_or(CanonError::Overflow)?,
            vars,
        })
    }

    /// `self / o` if `o` divides `self`.
    pub fn div(&self, o: &Mono) -> Option<Mono> {
        let mut vars = Vec::with_capacity(self.vars.len());
        let mut j = 0;
        for &(a, ea) in &self.vars {
            if j < o.vars.len() && o.vars[j].0 == a {
                let eb = o.vars[j].1;
                j += 1;
                match ea.cmp(&eb) {
                    Ordering::Less => return None,
                    Ordering::Equal => {}
                    Ordering::Greater => vars.push((a, ea - eb)),
                }
            } else {
                if j < o.vars.len() && o.vars[j].0 < a {
                    return None;
                }
                vars.push((a, ea));
            }
        }
        if j < o.vars.len() {
            return None;
        }
        Some(Mono {
            deg: self.deg - o.deg,
            vars,
        })
    }

    /// Greatest common divisor.
    pub fn gcd(&self, o: &Mono) -> Mono {
        let mut vars = Vec::new();
        let (mut i, mut j) = (0, 0);
        while i < self.vars.len() && j < o.vars.len() {
            let (a, ea) = self.vars[i];
            let (b, eb) = o.vars[j];
            match a.cmp(&b) {
                Ordering::Less => i += 1,
                Ordering::Greater => j += 1,
                Ordering::Equal => {
                    vars.push((a, ea.min(eb)));
                    i += 1;
                    j += 1;
                }
            }
        }
        Mono {
            deg: vars.iter().map(|v| v.1).sum(),
            vars,
        }
    }

    /// As an expression (a product of atom powers).
    pub fn to_expr(&self) -> Expr {
        Expr::mul_all(self.vars.iter().map(|(a, e)| a.0.powi(*e as i64)))
    }
}

impl PartialOrd for Mono {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

/// Graded lexicographic order; structurally smaller atoms rank higher.
impl Ord for Mono {
    fn cmp(&self, o: &Self) -> Ordering {
        match self.deg.cmp(&o.deg) {
            Ordering::Equal => {}
            c => return c,
        }
        for (&(a, ea), &(b, eb)) in self.vars.iter().zip(o.vars.iter()) {
            if a != b {
                return if a < b {
                    Ordering::Greater
                } else {
                    Ordering::Less
                };
            }
            match ea.cmp(&eb) {
                Ordering::Equal => {}
                c => return c,
            }
        }
        self.vars.len().cmp(&o.vars.len())
    }
}

/// A polynomial: nonzero terms sorted by decreasing monomial.
#[derive(Clone, PartialEq, Eq, Hash, Debug, Default)]
pub struct Poly {
    terms: Vec<(Mono, Rational)>,
}

impl PartialOrd for Poly {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Poly {
    fn cmp(&self, o: &Self) -> Ordering {
        for ((ma, ca), (mb, cb)) in self.terms.iter().zip(o.terms.iter()) {
            match ma.cmp(mb).then_with(|| ca.cmp(cb)) {
                Ordering::Equal => {}
                c => return c,
            }
        }
        self.terms.len().cmp(&o.terms.len())
    }
}

/// What a trigonometric atom is: `sin(angle)` or `cos(angle)` with the angle
/// a canonical polynomial whose leading coefficient is positive.
#[derive(Clone, Debug)]
struct TrigAtom {
    sin: bool,
    angle: Poly,
    /// `None` for a polynomial angle; `Some(u)` for a multiple of an opaque
    /// angle atom `u` (a rational function). Only atoms of the same class
    /// combine by the product-to-sum formulas.
    class: Option<Atom>,
}

/// Side relations used to reduce monomials:
///
/// * `atom^q = replacement` (roots: `(B^(1/q))^q = B`);
/// * products of two trigonometric atoms by the product-to-sum formulas
///   (`cos a cos b = (cos(a - b) + cos(a + b))/2`, ...), so a reduced monomial
///   has at most one trigonometric factor per class. The functions `1`,
///   `cos(k.x)`, `sin(k.x)` (one per angle up to sign) are linearly
///   independent, so this Fourier form of a trigonometric polynomial is unique
///   for any number of angles and any multiples. Polynomial angles form one
///   class; each opaque angle `u` (a rational function, registered with
///   [`Rules::opaque_angle`]) forms its own class of multiples `k u`.
#[derive(Clone, Debug)]
pub struct Rules {
    rules: HashMap<Atom, (u32, Poly)>,
    trig: RefCell<HashMap<Atom, TrigAtom>>,
    opaque: RefCell<FxHashSet<Atom>>,
    /// Memo of reduced products of two trigonometric atoms.
    products: RefCell<HashMap<(Atom, Atom), Poly>>,
    max_terms: usize,
}

impl Default for Rules {
    fn default() -> Rules {
        Rules::new()
    }
}

impl Rules {
    /// No relations; polynomials up to [`MAX_TERMS`] terms.
    pub fn new() -> Rules {
        Rules::with_budget(MAX_TERMS)
    }

    /// No relations; any intermediate polynomial with more than `max_terms`
    /// terms stops the computation with [`CanonError::TooLarge`].
    pub fn with_budget(max_terms: usize) -> Rules {
        Rules {
            rules: HashMap::default(),
            trig: RefCell::new(HashMap::default()),
            opaque: RefCell::new(FxHashSet::default()),
            products: RefCell::new(HashMap::default()),
            max_terms,
        }
    }

    /// The term budget.
    pub fn budget(&self) -> usize {
        self.max_terms
    }

    /// Register `a^q = p` (`p` must itself be reduced).
    pub fn insert(&mut self, a: Atom, q: u32, p: Poly) {
        self.rules.entry(a).or_insert((q, p));
    }

    /// Is there a relation for `a`?
    pub fn has(&self, a: Atom) -> bool {
        self.rules.contains_key(&a) || self.trig.borrow().contains_key(&a)
    }

    /// The root relations only (no product-to-sum reduction of sines and
    /// cosines).
    pub fn without_trig(&self) -> Rules {
        Rules {
            rules: self.rules.clone(),
            trig: RefCell::new(HashMap::default()),
            opaque: RefCell::new(FxHashSet::default()),
            products: RefCell::new(HashMap::default()),
            max_terms: self.max_terms,
        }
    }

    /// True if no relation is registered (plain polynomial arithmetic).
    pub fn is_trivial(&self) -> bool {
        self.rules.is_empty() && self.trig.borrow().is_empty()
    }

    /// Register `u` as an opaque angle: trigonometric atoms of its multiples
    /// form their own class.
    pub fn opaque_angle(&self, u: Atom) {
        self.opaque.borrow_mut().insert(u);
    }

    /// `sin(angle)` (or `cos(angle)`) as a reduced polynomial: a signed
    /// trigonometric atom (the angle sign-normalised so that its leading
    /// coefficient is positive), or a constant when the angle is 0 or the
    /// expression constructors fold it (a float angle).
    pub fn trig(&self, sin: bool, angle: &Poly) -> CResult<Poly> {
        if angle.is_zero() {
            return Ok(if sin {
                Poly::zero()
            } else {
                Poly::constant(Rational::ONE)
            });
        }
        let negative = angle.leading().is_some_and(|(_, c)| c.is_negative());
        let angle = if negative {
            angle.neg()?
        } else {
            angle.clone()
        };
        let ae = angle.to_expr();
        let e = if sin { ae.sin() } else { ae.cos() };
        let p = match e.node() {
            Node::Func(Func::Sin | Func::Cos, x) if *x == ae => {
                let class = match angle.terms() {
                    [(m, _)] if m.vars().len() == 1 && m.vars()[0].1 == 1 => {
                        let a = m.vars()[0].0;
                        self.opaque.borrow().contains(&a).then_some(a)
                    }
                    _ => None,
                };
                self.trig
                    .borrow_mut()
                    .entry(Atom(e))
                    .or_insert(TrigAtom { sin, angle, class });
                Poly::atom(Atom(e))
            }
            _ => constant_poly(e),
        };
        if negative && sin {
            p.neg()
        } else {
            Ok(p)
        }
    }

    /// The angle of a trigonometric atom, with `true` for `sin`.
    pub fn trig_angle(&self, a: Atom) -> Option<(bool, Poly)> {
        self.trig.borrow().get(&a).map(|t| (t.sin, t.angle.clone()))
    }

    fn rewrite(&self, m: &Mono) -> CResult<Option<(Mono, Poly)>> {
        if self.is_trivial() {
            return Ok(None);
        }
        for &(a, e) in &m.vars {
            if let Some((q, p)) = self.rules.get(&a) {
                if e >= *q {
                    return Ok(Some((m.with_exp(a, e - q), p.clone())));
                }
            }
        }
        let ta = {
            let trig = self.trig.borrow();
            if trig.is_empty() {
                return Ok(None);
            }
            // the first two trigonometric factors of one class
            let mut firsts: Vec<(Option<Atom>, Atom, u32)> = Vec::new();
            let mut pair = None;
            for &(a, e) in &m.vars {
                let Some(t) = trig.get(&a) else { continue };
                if e >= 2 {
                    pair = Some((a, e, a, e));
                    break;
                }
                match firsts.iter().find(|(c, _, _)| *c == t.class) {
                    Some(&(_, f, ef)) => {
                        pair = Some((f, ef, a, e));
                        break;
                    }
                    None => firsts.push((t.class, a, e)),
                }
            }
            let Some((a, ea, b, eb)) = pair else {
                return Ok(None);
            };
            let rest = if a == b {
                m.with_exp(a, ea - 2)
            } else {
                m.with_exp(a, ea - 1).with_exp(b, eb - 1)
            };
            if let Some(p) = self.products.borrow().get(&(a, b)) {
                return Ok(Some((rest, p.clone())));
            }
            (a, b, trig[&a].clone(), trig[&b].clone(), rest)
        };
        let (a, b, ta, tb, rest) = (ta.0, ta.1, ta.2, ta.3, ta.4);
        let sum = ta.angle.add(&tb.angle)?;
        let dif = ta.angle.sub(&tb.angle)?;
        let half = Rational::new(1, 2).ok_or(CanonError::Overflow)?;
        let (x, y, sign) = match (ta.sin, tb.sin) {
            // cos a cos b = (cos(a - b) + cos(a + b))/2
            (false, false) => (self.trig(false, &dif)?, self.trig(false, &sum)?, 1),
            // sin a sin b = (cos(a - b) - cos(a + b))/2
            (true, true) => (self.trig(false, &dif)?, self.trig(false, &sum)?, -1),
            // sin a cos b = (sin(a + b) + sin(a - b))/2
            (true, false) => (self.trig(true, &sum)?, self.trig(true, &dif)?, 1),
            // cos a sin b = (sin(a + b) - sin(a - b))/2
            (false, true) => (self.trig(true, &sum)?, self.trig(true, &dif)?, -1),
        };
        let y = if sign < 0 { y.neg()? } else { y };
        let p = x.add(&y)?.scale(half)?;
        self.products.borrow_mut().insert((a, b), p.clone());
        Ok(Some((rest, p)))
    }

    /// Collect terms into a reduced polynomial.
    pub fn collect<I: IntoIterator<Item = (Mono, Rational)>>(&self, terms: I) -> CResult<Poly> {
        let mut acc: HashMap<Mono, Rational> = HashMap::default();
        let mut work: Vec<(Mono, Rational)> = terms.into_iter().collect();
        while let Some((m, c)) = work.pop() {
            if c.is_zero() {
                continue;
            }
            if let Some((rest, p)) = self.rewrite(&m)? {
                for (pm, pc) in &p.terms {
                    work.push((rest.mul(pm)?, rmul(c, *pc)?));
                }
                if work.len() > self.max_terms {
                    return Err(CanonError::TooLarge);
                }
                continue;
            }
            match acc.get_mut(&m) {
                Some(v) => *v = radd(*v, c)?,
                None => {
                    acc.insert(m, c);
                    if acc.len() > self.max_terms {
                        return Err(CanonError::TooLarge);
                    }
                }
            }
        }
        let mut terms: Vec<(Mono, Rational)> =
            acc.into_iter().filter(|(_, c)| !c.is_zero()).collect();
        terms.sort_by(|a, b| b.0.cmp(&a.0));
        Ok(Poly { terms })
    }
}

/// A constant expression (rational or float) as a polynomial: floats are
/// sign-normalised atoms, as in the canonical form.
fn constant_poly(e: Expr) -> Poly {
    if let Some(r) = e.as_rational() {
        return Poly::constant(r);
    }
    match e.as_f64() {
        Some(v) if v < 0.0 => Poly::term(Mono::atom(Atom(Expr::float(-v)), 1), Rational::MINUS_ONE),
        _ => Poly::atom(Atom(e)),
    }
}

impl Poly {
    /// Zero.
    pub fn zero() -> Poly {
        Poly::default()
    }

    /// Terms as given (like monomials summed, no reduction by any relation).
    pub fn from_terms<I: IntoIterator<Item = (Mono, Rational)>>(terms: I) -> CResult<Poly> {
        let mut acc: HashMap<Mono, Rational> = HashMap::default();
        for (m, c) in terms {
            let v = acc.entry(m).or_insert(Rational::ZERO);
            *v = radd(*v, c)?;
        }
        let mut terms: Vec<(Mono, Rational)> =
            acc.into_iter().filter(|(_, c)| !c.is_zero()).collect();
        terms.sort_by(|a, b| b.0.cmp(&a.0));
        Ok(Poly { terms })
    }

    /// A constant.
    pub fn constant(c: Rational) -> Poly {
        Poly::term(Mono::one(), c)
    }

    /// A single term.
    pub fn term(m: Mono, c: Rational) -> Poly {
        if c.is_zero() {
            Poly::zero()
        } else {
            Poly {
                terms: vec![(m, c)],
            }
        }
    }

    /// The atom itself.
    pub fn atom(a: Atom) -> Poly {
        Poly::term(Mono::atom(a, 1), Rational::ONE)
    }

    /// Terms, leading (largest) first.
    pub fn terms(&self) -> &[(Mono, Rational)] {
        &self.terms
    }

    /// Number of terms.
    pub fn len(&self) -> usize {
        self.terms.len()
    }

    /// True if there are no terms (the zero polynomial).
    pub fn is_empty(&self) -> bool {
        self.terms.is_empty()
    }

    /// True if zero.
    pub fn is_zero(&self) -> bool {
        self.terms.is_empty()
    }

    /// The value if constant.
    pub fn as_constant(&self) -> Option<Rational> {
        match self.terms.as_slice() {
            [] => Some(Rational::ZERO),
            [(m, c)] if m.is_one() => Some(*c),
            _ => None,
        }
    }

    /// Leading term.
    pub fn leading(&self) -> Option<&(Mono, Rational)> {
        self.terms.first()
    }

    /// Sum.
    pub fn add(&self, o: &Poly) -> CResult<Poly> {
        let mut terms = Vec::with_capacity(self.terms.len() + o.terms.len());
        let (mut i, mut j) = (0, 0);
        while i < self.terms.len() && j < o.terms.len() {
            let (ma, ca) = &self.terms[i];
            let (mb, cb) = &o.terms[j];
            match ma.cmp(mb) {
                Ordering::Greater => {
                    terms.push((ma.clone(), *ca));
                    i += 1;
                }
                Ordering::Less => {
                    terms.push((mb.clone(), *cb));
                    j += 1;
                }
                Ordering::Equal => {
                    let c = radd(*ca, *cb)?;
                    if !c.is_zero() {
                        terms.push((ma.clone(), c));
                    }
                    i += 1;
                    j += 1;
                }
            }
        }
        terms.extend_from_slice(&self.terms[i..]);
        terms.extend_from_slice(&o.terms[j..]);
        Ok(Poly { terms })
    }

    /// Negation.
    pub fn neg(&self) -> CResult<Poly> {
        self.scale(Rational::MINUS_ONE)
    }

    /// Difference.
    pub fn sub(&self, o: &Poly) -> CResult<Poly> {
        self.add(&o.neg()?)
    }

    /// Multiply by a constant.
    pub fn scale(&self, c: Rational) -> CResult<Poly> {
        if c.is_zero() {
            return Ok(Poly::zero());
        }
        let terms = self
            .terms
            .iter()
            .map(|(m, a)| Ok((m.clone(), rmul(*a, c)?)))
            .collect::<CResult<Vec<_>>>()?;
        Ok(Poly { terms })
    }

    /// Multiply by `c * m`, reducing.
    pub fn mul_term(&self, m: &Mono, c: Rational, rules: &Rules) -> CResult<Poly> {
        if m.is_one() {
            return self.scale(c);
        }
        let mut v = Vec::with_capacity(self.terms.len());
        for (a, ca) in &self.terms {
            v.push((a.mul(m)?, rmul(*ca, c)?));
        }
        rules.collect(v)
    }

    /// Product, reduced.
    pub fn mul(&self, o: &Poly, rules: &Rules) -> CResult<Poly> {
        if self.is_zero() || o.is_zero() {
            return Ok(Poly::zero());
        }
        if let Some(c) = self.as_constant() {
            return o.scale(c);
        }
        if let Some(c) = o.as_constant() {
            return self.scale(c);
        }
        if self.terms.len().saturating_mul(o.terms.len()) > 4 * rules.max_terms {
            return Err(CanonError::TooLarge);
        }
        let mut v = Vec::with_capacity(self.terms.len() * o.terms.len());
        for (ma, ca) in &self.terms {
            for (mb, cb) in &o.terms {
                v.push((ma.mul(mb)?, rmul(*ca, *cb)?));
            }
        }
        rules.collect(v)
    }

    /// Non-negative integer power.
    pub fn pow(&self, n: u32, rules: &Rules) -> CResult<Poly> {
        let mut acc = Poly::constant(Rational::ONE);
        for _ in 0..n {
            acc = acc.mul(self, rules)?;
        }
        Ok(acc)
    }

    /// `self / g` if `g` divides `self` exactly (modulo the rules), by
    /// multivariate division on leading terms. May miss a divisor (returns
    /// `None`) but never returns a wrong quotient.
    pub fn div_exact(&self, g: &Poly, rules: &Rules) -> CResult<Option<Poly>> {
        let Some((lm_g, lc_g)) = g.leading() else {
            return Err(CanonError::DivisionByZero);
        };
        if let Some(c) = g.as_constant() {
            return Ok(Some(self.scale(rdiv(Rational::ONE, c)?)?));
        }
        if self.is_zero() {
            return Ok(Some(Poly::zero()));
        }
        // Cheap rejection: total degree.
        if g.terms.iter().map(|t| t.0.deg).max() > self.terms.iter().map(|t| t.0.deg).max()
            && rules.is_trivial()
        {
            return Ok(None);
        }
        let max_steps = 4 * self.terms.len() + 64;
        let mut r = self.clone();
        let mut q: Vec<(Mono, Rational)> = Vec::new();
        let mut steps = 0;
        while let Some((lm_r, lc_r)) = r.leading() {
            steps += 1;
            if steps > max_steps {
                return Ok(None);
            }
            let Some(t) = lm_r.div(lm_g) else {
                return Ok(None);
            };
            let c = rdiv(*lc_r, *lc_g)?;
            let sub = g.mul_term(&t, c, rules)?;
            q.push((t, c));
            r = r.sub(&sub)?;
        }
        Ok(Some(rules.collect(q)?))
    }

    /// Rational content with the sign of the leading coefficient: `self / content`
    /// has coprime integer coefficients and a positive leading coefficient.
    pub fn content(&self) -> CResult<Rational> {
        let Some((_, lc)) = self.leading() else {
            return Ok(Rational::ONE);
        };
        let mut g: i128 = 0;
        let mut l: i128 = 1;
        for (_, c) in &self.terms {
            g = igcd(g, c.numer());
            let d = c.denom();
            l = (l / igcd(l, d))
                .checked_mul(d)
                .ok_or(CanonError::Overflow)?;
        }
        let r = Rational::new(g, l).ok_or(CanonError::Overflow)?;
        if lc.is_negative() {
            rneg(r)
        } else {
            Ok(r)
        }
    }

    /// Greatest common monomial divisor of all terms.
    pub fn mono_gcd(&self) -> Mono {
        let mut it = self.terms.iter();
        let Some((first, _)) = it.next() else {
            return Mono::one();
        };
        let mut g = first.clone();
        for (m, _) in it {
            if g.is_one() {
                break;
            }
            g = g.gcd(m);
        }
        g
    }

    /// Divide every term by a monomial that divides all of them.
    pub fn div_mono(&self, m: &Mono) -> Poly {
        if m.is_one() {
            return self.clone();
        }
        let terms = self
            .terms
            .iter()
            .map(|(a, c)| (a.div(m).expect("monomial divides every term"), *c))
            .collect();
        Poly { terms }
    }

    /// As an expression (a sum of terms).
    pub fn to_expr(&self) -> Expr {
        Expr::add_all(
            self.terms
                .iter()
                .map(|(m, c)| Expr::rational(*c) * m.to_expr()),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(e: &[(&[(&str, u32)], i128)]) -> Poly {
        let rules = Rules::new();
        rules
            .collect(e.iter().map(|(vs, c)| {
                let mut m = Mono::one();
                for (n, k) in vs.iter() {
                    m = m.mul(&Mono::atom(Atom(Expr::sym(n)), *k)).unwrap();
                }
                (m, Rational::int(*c))
            }))
            .unwrap()
    }

    #[test]
    fn division() {
        let rules = Rules::new();
        // (x^2 - y^2) / (x - y) = x + y
        let f = p(&[(&[("x", 2)], 1), (&[("y", 2)], -1)]);
        let g = p(&[(&[("x", 1)], 1), (&[("y", 1)], -1)]);
        let q = f.div_exact(&g, &rules).unwrap().unwrap();
        assert_eq!(q, p(&[(&[("x", 1)], 1), (&[("y", 1)], 1)]));
        let h = p(&[(&[("x", 1)], 1), (&[], 1)]);
        assert_eq!(f.div_exact(&h, &rules).unwrap(), None);
    }

    #[test]
    fn content_and_gcd() {
        let f = p(&[(&[("x", 2), ("y", 1)], -6), (&[("x", 1), ("y", 1)], 4)]);
        assert_eq!(f.content().unwrap(), Rational::int(-2));
        assert_eq!(f.mono_gcd(), p(&[(&[("x", 1), ("y", 1)], 1)]).terms[0].0);
    }
}
