//! Unit suffixes in column headers (`alpha[deg]`, `t[ms]`, `x[mm]`) and their
//! conversion to SI.

use std::fmt;

/// What a channel measures. It decides which unit suffixes a column may carry
/// and which plausibility checks apply to it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Kind {
    /// Time, SI unit s.
    Time,
    /// An angle coordinate, SI unit rad.
    Angle,
    /// A length coordinate, SI unit m.
    Length,
    /// A voltage input, SI unit V.
    Voltage,
    /// A current, SI unit A.
    Current,
    /// A force input, SI unit N.
    Force,
    /// A torque input, SI unit N m.
    Torque,
    /// A quantity without a unit check (any known suffix is accepted, none converted
    /// unless it names a known unit).
    Other,
}

impl Kind {
    /// The SI unit symbol of this kind (empty for [`Kind::Other`]).
    pub fn si_unit(self) -> &'static str {
        match self {
            Kind::Time => "s",
            Kind::Angle => "rad",
            Kind::Length => "m",
            Kind::Voltage => "V",
            Kind::Current => "A",
            Kind::Force => "N",
            Kind::Torque => "N m",
            Kind::Other => "",
        }
    }
}

impl fmt::Display for Kind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let s = match self {
            Kind::Time => "time",
            Kind::Angle => "angle",
            Kind::Length => "length",
            Kind::Voltage => "voltage",
            Kind::Current => "current",
            Kind::Force => "force",
            Kind::Torque => "torque",
            Kind::Other => "quantity",
        };
        f.write_str(s)
    }
}

/// Known unit suffixes: (suffix, kind, factor to SI).
const UNITS: &[(&str, Kind, f64)] = &[
    ("s", Kind::Time, 1.0),
    ("ms", Kind::Time, 1e-3),
    ("us", Kind::Time, 1e-6),
    ("µs", Kind::Time, 1e-6),
    ("rad", Kind::Angle, 1.0),
    ("mrad", Kind::Angle, 1e-3),
    ("deg", Kind::Angle, std::f64::consts::PI / 180.0),
    ("rev", Kind::Angle, 2.0 * std::f64::consts::PI),
    ("m", Kind::Length, 1.0),
    ("cm", Kind::Length, 1e-2),
    ("mm", Kind::Length, 1e-3),
    ("V", Kind::Voltage, 1.0),
    ("mV", Kind::Voltage, 1e-3),
    ("A", Kind::Current, 1.0),
    ("mA", Kind::Current, 1e-3),
    ("N", Kind::Force, 1.0),
    ("Nm", Kind::Torque, 1.0),
    ("N m", Kind::Torque, 1.0),
    ("N*m", Kind::Torque, 1.0),
    ("N.m", Kind::Torque, 1.0),
];

/// A known unit: its kind and the factor that converts it to SI.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Unit {
    /// The suffix as written in the header.
    pub symbol: &'static str,
    /// What the unit measures.
    pub kind: Kind,
    /// Multiply a value by this to get SI.
    pub factor: f64,
}

/// Looks up a unit suffix (case-sensitive: `mm` is not `Mm`).
pub fn lookup_unit(symbol: &str) -> Option<Unit> {
    UNITS
        .iter()
        .find(|(s, _, _)| *s == symbol)
        .map(|&(symbol, kind, factor)| Unit {
            symbol,
            kind,
            factor,
        })
}

/// The known suffixes for a kind, for help texts.
pub fn known_units(kind: Kind) -> Vec<&'static str> {
    UNITS
        .iter()
        .filter(|(_, k, _)| kind == Kind::Other || *k == kind)
        .map(|(s, _, _)| *s)
        .collect()
}

/// Splits a header like `alpha[deg]` or `alpha [deg]` into (`alpha`, Some(`deg`)).
/// A header without brackets gives (`header`, None). Text after `]` is ignored
/// only if it is whitespace; otherwise the whole header is the name.
pub fn split_header(header: &str) -> (&str, Option<&str>) {
    let h = header.trim();
    if let Some(open) = h.find('[') {
        if let Some(rest) = h.strip_suffix(']') {
            if open < rest.len() {
                let name = h[..open].trim();
                let unit = rest[open + 1..].trim();
                if !name.is_empty() {
                    return (name, Some(unit));
                }
            }
        }
    }
    (h, None)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splits_headers() {
        assert_eq!(split_header("alpha[deg]"), ("alpha", Some("deg")));
        assert_eq!(split_header(" x [mm] "), ("x", Some("mm")));
        assert_eq!(split_header("Vm"), ("Vm", None));
        assert_eq!(split_header("[deg]"), ("[deg]", None));
    }

    #[test]
    fn converts() {
        let u = lookup_unit("deg").unwrap();
        assert!((180.0 * u.factor - std::f64::consts::PI).abs() < 1e-15);
        assert_eq!(lookup_unit("cm").unwrap().kind, Kind::Length);
        assert!(lookup_unit("furlong").is_none());
    }
}
