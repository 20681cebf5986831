//! Physical units and dimensions.
//!
//! A [`Dim`] is a product of SI base units (kg, m, s, A) with rational
//! exponents; radians are dimensionless (SI), so a generalised force on an angle
//! is an energy (N*m) and on a length a force (N). A [`Unit`] is a dimension
//! plus an exact [`Scale`] to SI (`ratio * pi^pi_power`), e.g. `deg` is
//! `pi/180` rad and `rpm` is `2*pi/60` rad/s.

use std::fmt;
use std::ops::{Add, Div, Mul, Neg};

/// A small exact rational number (always normalised, `den > 0`).
///
/// Arithmetic saturates instead of overflowing (only absurd inputs reach that).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Ratio {
    /// Numerator.
    pub num: i64,
    /// Denominator (> 0).
    pub den: i64,
}

fn gcd(mut a: i128, mut b: i128) -> i128 {
    a = a.abs();
    b = b.abs();
    while b != 0 {
        let t = a % b;
        a = b;
        b = t;
    }
    a
}

const LIMIT: i128 = 1 << 62;

impl Ratio {
    /// Zero.
    pub const ZERO: Ratio = Ratio { num: 0, den: 1 };
    /// One.
    pub const ONE: Ratio = Ratio { num: 1, den: 1 };

    /// `num/den`, normalised; `den == 0` gives zero.
    pub fn new(num: i64, den: i64) -> Ratio {
        Ratio::from_i128(num as i128, den as i128)
    }

    fn from_i128(mut num: i128, mut den: i128) -> Ratio {
        if den == 0 {
            return Ratio::ZERO;
        }
        if den < 0 {
            num = -num;
            den = -den;
        }
        let g = gcd(num, den).max(1);
        num /= g;
        den /= g;
        while num.abs() > LIMIT || den > LIMIT {
            num /= 2;
            den = (den / 2).max(1);
        }
        Ratio {
            num: num as i64,
            den: den as i64,
        }
    }

    /// An integer.
    pub fn int(n: i64) -> Ratio {
        Ratio::new(n, 1)
    }

    fn add_r(self, o: Ratio) -> Ratio {
        Ratio::from_i128(
            self.num as i128 * o.den as i128 + o.num as i128 * self.den as i128,
            self.den as i128 * o.den as i128,
        )
    }

    fn mul_r(self, o: Ratio) -> Ratio {
        Ratio::from_i128(
            self.num as i128 * o.num as i128,
            self.den as i128 * o.den as i128,
        )
    }

    fn neg_r(self) -> Ratio {
        Ratio::from_i128(-(self.num as i128), self.den as i128)
    }

    /// Reciprocal (zero stays zero).
    pub fn recip(self) -> Ratio {
        Ratio::from_i128(self.den as i128, self.num as i128)
    }

    /// True for zero.
    pub fn is_zero(self) -> bool {
        self.num == 0
    }

    /// As a float.
    pub fn to_f64(self) -> f64 {
        self.num as f64 / self.den as f64
    }

    /// Parses a decimal literal such as `2`, `0.5`, `1e-3` exactly.
    pub fn parse_decimal(text: &str) -> Option<Ratio> {
        let (mant, exp) = match text.find(['e', 'E']) {
            Some(i) => (&text[..i], text[i + 1..].parse::<i32>().ok()?),
            None => (text, 0),
        };
        let (neg, mant) = match mant.strip_prefix('-') {
            Some(m) => (true, m),
            None => (false, mant),
        };
        let (ip, fp) = match mant.find('.') {
            Some(i) => (&mant[..i], &mant[i + 1..]),
            None => (mant, ""),
        };
        let digits = format!("{ip}{fp}");
        if digits.is_empty() || digits.len() > 17 || !digits.bytes().all(|b| b.is_ascii_digit()) {
            return None;
        }
        let mut num: i128 = digits.parse().ok()?;
        let e = exp - fp.len() as i32;
        if !(-18..=18).contains(&e) {
            return None;
        }
        let mut den: i128 = 1;
        if e >= 0 {
            num = num.checked_mul(10i128.pow(e as u32))?;
        } else {
            den = 10i128.pow((-e) as u32);
        }
        if neg {
            num = -num;
        }
        if num.abs() > LIMIT || den > LIMIT {
            return None;
        }
        Some(Ratio::from_i128(num, den))
    }
}

impl fmt::Display for Ratio {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.den == 1 {
            write!(f, "{}", self.num)
        } else {
            write!(f, "{}/{}", self.num, self.den)
        }
    }
}

/// Names of the SI base units, in the order of [`Dim`]'s exponents.
pub const BASE_UNITS: [&str; 4] = ["kg", "m", "s", "A"];

/// A physical dimension: exponents of kg, m, s, A.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Dim(pub [Ratio; 4]);

impl Dim {
    /// Dimensionless.
    pub const NONE: Dim = Dim([Ratio::ZERO; 4]);

    fn base(i: usize) -> Dim {
        let mut d = Dim::NONE;
        d.0[i] = Ratio::ONE;
        d
    }

    /// kg
    pub fn mass() -> Dim {
        Dim::base(0)
    }
    /// m
    pub fn length() -> Dim {
        Dim::base(1)
    }
    /// s
    pub fn time() -> Dim {
        Dim::base(2)
    }
    /// A
    pub fn current() -> Dim {
        Dim::base(3)
    }
    /// kg*m^2/s^2 (energy, torque).
    pub fn energy() -> Dim {
        Dim::mass()
            .mul(Dim::length().powi(2))
            .div(Dim::time().powi(2))
    }
    /// kg*m/s^2.
    pub fn force() -> Dim {
        Dim::mass().mul(Dim::length()).div(Dim::time().powi(2))
    }

    fn mul_d(self, o: Dim) -> Dim {
        let mut r = self;
        for i in 0..4 {
            r.0[i] = r.0[i].add(o.0[i]);
        }
        r
    }

    fn div_d(self, o: Dim) -> Dim {
        self.mul(o.pow(Ratio::int(-1)))
    }

    /// Rational power.
    pub fn pow(self, e: Ratio) -> Dim {
        let mut r = self;
        for x in r.0.iter_mut() {
            *x = x.mul(e);
        }
        r
    }

    /// Integer power.
    pub fn powi(self, e: i64) -> Dim {
        self.pow(Ratio::int(e))
    }

    /// True if dimensionless.
    pub fn is_none(self) -> bool {
        self.0.iter().all(|r| r.is_zero())
    }

    /// The dimension in SI base units, e.g. `kg*m^2/s^2`, `1` if dimensionless.
    pub fn base_form(self) -> String {
        let mut num = Vec::new();
        let mut den = Vec::new();
        for (i, e) in self.0.iter().enumerate() {
            if e.is_zero() {
                continue;
            }
            let (list, e) = if e.num < 0 {
                (&mut den, e.neg())
            } else {
                (&mut num, *e)
            };
            if e == Ratio::ONE {
                list.push(BASE_UNITS[i].to_string());
            } else if e.den == 1 {
                list.push(format!("{}^{}", BASE_UNITS[i], e));
            } else {
                list.push(format!("{}^({})", BASE_UNITS[i], e));
            }
        }
        let n = if num.is_empty() {
            "1".to_string()
        } else {
            num.join("*")
        };
        if den.is_empty() {
            n
        } else {
            format!("{n}/{}", den.join("/"))
        }
    }

    /// A familiar name for common dimensions (`N*m`, `N`, `V`, ...), if any.
    pub fn common_name(self) -> Option<&'static str> {
        let table: [(&str, Dim); 7] = [
            ("N*m", Dim::energy()),
            ("N", Dim::force()),
            ("W", Dim::energy().div(Dim::time())),
            ("V", Dim::energy().div(Dim::time()).div(Dim::current())),
            (
                "ohm",
                Dim::energy().div(Dim::time()).div(Dim::current().powi(2)),
            ),
            ("N*m*s", Dim::energy().mul(Dim::time())),
            ("N*s/m", Dim::force().mul(Dim::time()).div(Dim::length())),
        ];
        table.iter().find(|(_, d)| *d == self).map(|(n, _)| *n)
    }
}

impl fmt::Display for Dim {
    /// Base form, followed by a familiar name when there is one:
    /// `kg*m^2/s^2 (N*m)`, `1 (dimensionless)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.is_none() {
            return f.write_str("1 (dimensionless)");
        }
        match self.common_name() {
            Some(n) => write!(f, "{n} (= {})", self.base_form()),
            None => f.write_str(&self.base_form()),
        }
    }
}

/// Exact factor from a unit to SI: `ratio * pi^pi_power`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Scale {
    /// Rational part.
    pub ratio: Ratio,
    /// Power of pi.
    pub pi_power: i32,
}

impl Scale {
    /// No scaling.
    pub const ONE: Scale = Scale {
        ratio: Ratio::ONE,
        pi_power: 0,
    };

    fn mul_s(self, o: Scale) -> Scale {
        Scale {
            ratio: self.ratio.mul(o.ratio),
            pi_power: self.pi_power.saturating_add(o.pi_power),
        }
    }

    /// Integer power.
    pub fn powi(self, e: i32) -> Scale {
        let mut r = Scale::ONE;
        let b = if e < 0 {
            Scale {
                ratio: self.ratio.recip(),
                pi_power: -self.pi_power,
            }
        } else {
            self
        };
        for _ in 0..e.unsigned_abs().min(64) {
            r = r.mul(b);
        }
        r
    }

    /// As a float.
    pub fn to_f64(self) -> f64 {
        self.ratio.to_f64() * std::f64::consts::PI.powi(self.pi_power)
    }

    /// True for exactly 1.
    pub fn is_one(self) -> bool {
        self == Scale::ONE
    }
}

impl fmt::Display for Scale {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.pi_power {
            0 => write!(f, "{}", self.ratio),
            1 => write!(f, "{}*pi", self.ratio),
            p => write!(f, "{}*pi^{}", self.ratio, p),
        }
    }
}

/// A resolved unit: dimension and scale to SI.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Unit {
    /// Physical dimension.
    pub dim: Dim,
    /// Value in this unit times `scale` = value in SI.
    pub scale: Scale,
}

impl Unit {
    /// Dimensionless, scale 1.
    pub const ONE: Unit = Unit {
        dim: Dim::NONE,
        scale: Scale::ONE,
    };
}

/// One entry of the unit table.
#[derive(Debug, Clone, Copy)]
pub struct UnitDef {
    /// Symbol as written in brackets.
    pub name: &'static str,
    /// Dimension.
    pub dim: fn() -> Dim,
    /// Scale to SI.
    pub scale: Scale,
    /// What it is.
    pub doc: &'static str,
}

const fn sc(num: i64, den: i64, pi_power: i32) -> Scale {
    Scale {
        ratio: Ratio { num, den },
        pi_power,
    }
}

fn d_none() -> Dim {
    Dim::NONE
}
fn d_per_s() -> Dim {
    Dim::time().powi(-1)
}
fn d_energy_per_s() -> Dim {
    Dim::energy().div(Dim::time())
}
fn d_volt() -> Dim {
    d_energy_per_s().div(Dim::current())
}
fn d_ohm() -> Dim {
    d_volt().div(Dim::current())
}

/// The known units. Add rows here to support more.
pub const UNITS: &[UnitDef] = &[
    UnitDef {
        name: "kg",
        dim: Dim::mass,
        scale: sc(1, 1, 0),
        doc: "kilogram",
    },
    UnitDef {
        name: "g",
        dim: Dim::mass,
        scale: sc(1, 1000, 0),
        doc: "gram",
    },
    UnitDef {
        name: "m",
        dim: Dim::length,
        scale: sc(1, 1, 0),
        doc: "metre",
    },
    UnitDef {
        name: "cm",
        dim: Dim::length,
        scale: sc(1, 100, 0),
        doc: "centimetre",
    },
    UnitDef {
        name: "mm",
        dim: Dim::length,
        scale: sc(1, 1000, 0),
        doc: "millimetre",
    },
    UnitDef {
        name: "s",
        dim: Dim::time,
        scale: sc(1, 1, 0),
        doc: "second",
    },
    UnitDef {
        name: "ms",
        dim: Dim::time,
        scale: sc(1, 1000, 0),
        doc: "millisecond",
    },
    UnitDef {
        name: "A",
        dim: Dim::current,
        scale: sc(1, 1, 0),
        doc: "ampere",
    },
    UnitDef {
        name: "mA",
        dim: Dim::current,
        scale: sc(1, 1000, 0),
        doc: "milliampere",
    },
    UnitDef {
        name: "V",
        dim: d_volt,
        scale: sc(1, 1, 0),
        doc: "volt",
    },
    UnitDef {
        name: "ohm",
        dim: d_ohm,
        scale: sc(1, 1, 0),
        doc: "ohm",
    },
    UnitDef {
        name: "N",
        dim: Dim::force,
        scale: sc(1, 1, 0),
        doc: "newton",
    },
    UnitDef {
        name: "J",
        dim: Dim::energy,
        scale: sc(1, 1, 0),
        doc: "joule",
    },
    UnitDef {
        name: "W",
        dim: d_energy_per_s,
        scale: sc(1, 1, 0),
        doc: "watt",
    },
    UnitDef {
        name: "rad",
        dim: d_none,
        scale: sc(1, 1, 0),
        doc: "radian (dimensionless)",
    },
    UnitDef {
        name: "deg",
        dim: d_none,
        scale: sc(1, 180, 1),
        doc: "degree = pi/180 rad",
    },
    UnitDef {
        name: "rev",
        dim: d_none,
        scale: sc(2, 1, 1),
        doc: "revolution = 2*pi rad",
    },
    UnitDef {
        name: "rpm",
        dim: d_per_s,
        scale: sc(1, 30, 1),
        doc: "revolution per minute = 2*pi/60 rad/s",
    },
    UnitDef {
        name: "Hz",
        dim: d_per_s,
        scale: sc(1, 1, 0),
        doc: "hertz = 1/s",
    },
];

/// Looks up a unit symbol in [`UNITS`].
pub fn lookup(name: &str) -> Option<&'static UnitDef> {
    UNITS.iter().find(|u| u.name == name)
}

/// What an unknown unit name was meant to be, for quick fixes, in this
/// order: a known unit that differs only in case (`hz` -> `Hz`); else the
/// products of known units its letters spell, as a unit is written on paper
/// (`kgm` -> `kg*m`, so `[kgm^2]` becomes `[kg*m^2]`; products of two units
/// of one dimension, `kg*g`, are no reading), with a plural `s` dropped as
/// another reading (`kgs`: kg*s or kg); else the known units nearest in
/// spelling ([`super::check::suggest`]: `kgg` -> `kg`). The readings are
/// returned only when they all have one dimension: when they disagree (`kgs`,
/// or `Nms`: N*m*s, an energy times a time, and N*ms, a force times a time)
/// what the text meant is not known and the result is empty, so a quick fix
/// never changes the dimension the author wrote.
pub fn readings(name: &str) -> Vec<String> {
    let mut out: Vec<(String, Dim)> = UNITS
        .iter()
        .filter(|u| u.name != name && u.name.eq_ignore_ascii_case(name))
        .map(|u| (u.name.to_string(), (u.dim)()))
        .collect();
    if out.is_empty() {
        out = spellings(name);
        if let Some(u) = name
            .strip_suffix('s')
            .filter(|n| n.len() >= 2)
            .and_then(lookup)
        {
            out.push((u.name.to_string(), (u.dim)()));
        }
    }
    if out.is_empty() {
        out = super::check::suggest(name, UNITS.iter().map(|u| u.name))
            .into_iter()
            .filter_map(|n| lookup(&n).map(|u| (n, (u.dim)())))
            .collect();
        // only the nearest: a farther candidate is a different guess
        if let Some(best) = out
            .iter()
            .map(|(n, _)| super::check::edit_distance(name, n))
            .min()
        {
            out.retain(|(n, _)| super::check::edit_distance(name, n) == best);
        }
    }
    match out.first() {
        Some((_, d)) if out.iter().all(|(_, e)| e == d) => {
            out.into_iter().map(|(n, _)| n).collect()
        }
        _ => Vec::new(),
    }
}

/// Most readings [`spellings`] collects: the search stops there (a name
/// with more readings than this is no unit anyone meant).
const MAX_SPELLINGS: usize = 16;

/// Every way `name` is a concatenation of two or more known unit symbols of
/// different dimensions, as `a*b*...` with its dimension.
fn spellings(name: &str) -> Vec<(String, Dim)> {
    // each part has a dimension the earlier ones lack, so the depth is at
    // most the number of distinct dimensions in UNITS
    fn go(rest: &str, parts: &mut Vec<&'static UnitDef>, out: &mut Vec<(String, Dim)>) {
        if out.len() >= MAX_SPELLINGS {
            return;
        }
        if rest.is_empty() {
            if parts.len() >= 2 {
                let text = parts.iter().map(|u| u.name).collect::<Vec<_>>().join("*");
                let dim = parts.iter().fold(Dim::NONE, |d, u| d * (u.dim)());
                out.push((text, dim));
            }
            return;
        }
        for u in UNITS {
            let fresh = parts.iter().all(|p| (p.dim)() != (u.dim)());
            if let Some(r) = rest.strip_prefix(u.name).filter(|_| fresh) {
                parts.push(u);
                go(r, parts, out);
                parts.pop();
            }
        }
    }
    let mut out = Vec::new();
    go(name, &mut Vec::new(), &mut out);
    out
}

/// A unit expression that could not be understood. `start..end` are byte
/// offsets into the unit text.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnitError {
    /// Start of the offending part (byte offset in the unit text).
    pub start: usize,
    /// End of the offending part.
    pub end: usize,
    /// What is wrong.
    pub message: String,
    /// How to fix it.
    pub help: String,
}

/// Parses a unit expression such as `kg*m^2`, `N*m*s/rad`, `m/s^2`, `1/s`,
/// `m^(1/2)` or `1` (an empty text is dimensionless too). `/` applies to the
/// single factor after it (`kg/m/s` = kg m^-1 s^-1).
pub fn parse_unit(text: &str) -> Result<Unit, UnitError> {
    let b = text.as_bytes();
    let n = b.len();
    let mut i = 0;
    let mut unit = Unit::ONE;
    let skip = |i: &mut usize| {
        while *i < n && (b[*i] == b' ' || b[*i] == b'\t') {
            *i += 1;
        }
    };
    let err = |s: usize, e: usize, m: String, h: &str| UnitError {
        start: s,
        end: e.max(s + 1).min(n.max(s)),
        message: m,
        help: h.to_string(),
    };
    skip(&mut i);
    if i == n {
        return Ok(Unit::ONE);
    }
    let mut sign: i64 = 1;
    loop {
        skip(&mut i);
        let s = i;
        let mut fdim = Dim::NONE;
        let mut fscale = Scale::ONE;
        if i < n && (b[i] as char).is_ascii_alphabetic() {
            while i < n && ((b[i] as char).is_ascii_alphanumeric() || b[i] == b'_') {
                i += 1;
            }
            let name = &text[s..i];
            match lookup(name) {
                Some(u) => {
                    fdim = (u.dim)();
                    fscale = u.scale;
                }
                None => {
                    let known: Vec<&str> = UNITS.iter().map(|u| u.name).collect();
                    return Err(err(
                        s,
                        i,
                        format!("unknown unit `{name}`"),
                        &format!(
                            "known units: {}; combine them with * / ^, e.g. `N*m*s/rad`",
                            known.join(" ")
                        ),
                    ));
                }
            }
        } else if i < n && b[i] == b'1' && !(i + 1 < n && (b[i + 1] as char).is_ascii_digit()) {
            i += 1;
        } else {
            return Err(err(
                s,
                s + 1,
                "expected a unit name".to_string(),
                "write a unit such as `kg`, `m/s^2` or `N*m`, or `1` for dimensionless",
            ));
        }
        skip(&mut i);
        let mut exp = Ratio::ONE;
        if i < n && b[i] == b'^' {
            i += 1;
            skip(&mut i);
            let es = i;
            let paren = i < n && b[i] == b'(';
            if paren {
                i += 1;
            }
            let mut j = i;
            if j < n && b[j] == b'-' {
                j += 1;
            }
            while j < n && (b[j].is_ascii_digit() || (paren && (b[j] == b'/' || b[j] == b' '))) {
                j += 1;
            }
            let body = text[i..j].replace(' ', "");
            let parsed = match body.split_once('/') {
                Some((p, q)) => match (p.parse::<i64>(), q.parse::<i64>()) {
                    (Ok(p), Ok(q)) if q != 0 => Some(Ratio::new(p, q)),
                    _ => None,
                },
                None => body.parse::<i64>().ok().map(Ratio::int),
            };
            i = j;
            if paren {
                if i < n && b[i] == b')' {
                    i += 1;
                } else {
                    return Err(err(
                        es,
                        i,
                        "unclosed `(` in unit exponent".into(),
                        "write e.g. `m^(1/2)`",
                    ));
                }
            }
            match parsed {
                Some(e) if e.num.abs() <= 12 && e.den <= 12 => exp = e,
                _ => {
                    return Err(err(
                        es,
                        i,
                        "bad unit exponent".into(),
                        "exponents are small integers like `^2`, `^-1`, or `^(1/2)`",
                    ))
                }
            }
        }
        let e = exp.mul(Ratio::int(sign));
        unit.dim = unit.dim.mul(fdim.pow(e));
        if e.den == 1 {
            unit.scale = unit.scale.mul(fscale.powi(e.num as i32));
        } else if !fscale.is_one() {
            return Err(err(
                s,
                i,
                "fractional power of a scaled unit".into(),
                "use SI units with fractional exponents",
            ));
        }
        skip(&mut i);
        if i == n {
            return Ok(unit);
        }
        match b[i] {
            b'*' => sign = 1,
            b'/' => sign = -1,
            _ => {
                return Err(err(
                    i,
                    i + 1,
                    format!(
                        "unexpected `{}` in unit",
                        text[i..].chars().next().unwrap_or(' ')
                    ),
                    "units are products and quotients like `kg*m^2` or `m/s^2`",
                ))
            }
        }
        i += 1;
    }
}

impl Add for Ratio {
    type Output = Ratio;
    fn add(self, o: Ratio) -> Ratio {
        self.add_r(o)
    }
}

impl Mul for Ratio {
    type Output = Ratio;
    fn mul(self, o: Ratio) -> Ratio {
        self.mul_r(o)
    }
}

impl Neg for Ratio {
    type Output = Ratio;
    fn neg(self) -> Ratio {
        self.neg_r()
    }
}

impl Mul for Dim {
    type Output = Dim;
    fn mul(self, o: Dim) -> Dim {
        self.mul_d(o)
    }
}

impl Div for Dim {
    type Output = Dim;
    fn div(self, o: Dim) -> Dim {
        self.div_d(o)
    }
}

impl Mul for Scale {
    type Output = Scale;
    fn mul(self, o: Scale) -> Scale {
        self.mul_s(o)
    }
}
