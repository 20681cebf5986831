//! Printing expressions as a person writes them, and as LaTeX.
//!
//! Plain form: `J2h*sin(alpha)*cos(alpha)*theta'^2 - m2*g*l2*sin(alpha)`.
//! Products print their rational coefficient first, then parameters, then
//! functions, then velocities and accelerations; negative powers go to a
//! denominator (`a*b/(c*d)`), a negative coefficient becomes a leading minus.

use std::cmp::Ordering;
use std::fmt::{self, Write};

use super::expr::{structural_cmp, Expr, Node};
use super::rational::Rational;

const PREC_ADD: u8 = 1;
const PREC_MUL: u8 = 2;
const PREC_POW: u8 = 3;

fn factor_class(e: Expr) -> u8 {
    let (b, _) = e.base_and_exp();
    match b.node() {
        Node::Rational(_) | Node::Float(_) => 0,
        Node::Symbol(s) if s.name().ends_with('\'') => 3,
        Node::Symbol(_) => 1,
        Node::Func(..) | Node::Atan2(..) => 2,
        _ => 1,
    }
}

/// Factors in printing order.
fn print_order(factors: &[Expr]) -> Vec<Expr> {
    let mut v = factors.to_vec();
    v.sort_by(|a, b| match factor_class(*a).cmp(&factor_class(*b)) {
        Ordering::Equal => {
            let (ba, ea) = a.base_and_exp();
            let (bb, eb) = b.base_and_exp();
            structural_cmp(ba, bb).then_with(|| structural_cmp(ea, eb))
        }
        o => o,
    });
    v
}

/// Terms of a sum in printing order: positive leading term where possible,
/// lower-degree constant last.
fn term_order(terms: &[Expr]) -> Vec<Expr> {
    let mut v = terms.to_vec();
    v.sort_by(|a, b| {
        let ca = a.is_constant();
        let cb = b.is_constant();
        ca.cmp(&cb).then_with(|| structural_cmp(*a, *b))
    });
    // Prefer a term with positive coefficient first.
    if let Some(i) = v.iter().position(|t| !t.coeff_and_rest().0.is_negative()) {
        let t = v.remove(i);
        v.insert(0, t);
    }
    v
}

fn fmt_float(x: f64) -> String {
    if x.is_nan() {
        return "NaN".into();
    }
    if x.is_infinite() {
        return if x > 0.0 { "inf".into() } else { "-inf".into() };
    }
    let s = format!("{x:e}");
    let plain = format!("{x}");
    if plain.len() <= s.len() {
        plain
    } else {
        s
    }
}

/// Writes `e` in plain form with the surrounding precedence `outer`.
/// A sum in either notation: terms in print order, a negative coefficient
/// written as ` - ` with its absolute value, parentheses (`parens`) when
/// the context binds tighter than `+`.
fn write_sum(
    out: &mut String,
    terms: &[Expr],
    outer: u8,
    parens: (&str, &str),
    term: fn(&mut String, Expr, u8),
    product: fn(&mut String, Rational, Expr, u8),
) {
    let needs = outer > PREC_ADD;
    if needs {
        out.push_str(parens.0);
    }
    for (i, t) in term_order(terms).into_iter().enumerate() {
        let (c, rest) = t.coeff_and_rest();
        if i == 0 {
            term(out, t, PREC_ADD);
        } else if c.is_negative() {
            out.push_str(" - ");
            product(out, c.abs(), rest, PREC_ADD + 1);
        } else {
            out.push_str(" + ");
            term(out, t, PREC_ADD + 1);
        }
    }
    if needs {
        out.push_str(parens.1);
    }
}

fn write_plain(out: &mut String, e: Expr, outer: u8) {
    match e.node() {
        Node::Rational(r) => {
            let needs =
                (r.is_negative() && outer > PREC_ADD) || (!r.is_integer() && outer > PREC_MUL);
            if needs {
                out.push('(');
            }
            let _ = write!(out, "{r}");
            if needs {
                out.push(')');
            }
        }
        Node::Float(b) => {
            let v = b.value();
            let needs = v < 0.0 && outer > PREC_ADD;
            if needs {
                out.push('(');
            }
            out.push_str(&fmt_float(v));
            if needs {
                out.push(')');
            }
        }
        Node::Symbol(s) | Node::Named(s, _) => out.push_str(s.name()),
        Node::Add(terms) => write_sum(out, terms, outer, ("(", ")"), write_plain, write_product),
        Node::Mul(_) => {
            let (c, rest) = e.coeff_and_rest();
            if c.is_negative() {
                let needs = outer > PREC_ADD;
                if needs {
                    out.push('(');
                }
                out.push('-');
                write_product(out, c.abs(), rest, PREC_MUL);
                if needs {
                    out.push(')');
                }
            } else {
                write_product(out, c, rest, outer);
            }
        }
        Node::Pow(b, x) => {
            if let Some(r) = x.as_rational() {
                if r.is_negative() {
                    write_product(out, Rational::ONE, e, outer);
                    return;
                }
                if r == Rational::new(1, 2).unwrap() {
                    out.push_str("sqrt(");
                    write_plain(out, *b, 0);
                    out.push(')');
                    return;
                }
            }
            let needs = outer > PREC_POW;
            if needs {
                out.push('(');
            }
            write_plain(out, *b, PREC_POW + 1);
            out.push('^');
            write_plain(out, *x, PREC_POW + 1);
            if needs {
                out.push(')');
            }
        }
        Node::Func(f, x) => {
            out.push_str(f.name());
            out.push('(');
            write_plain(out, *x, 0);
            out.push(')');
        }
        Node::Atan2(y, x) => {
            out.push_str("atan2(");
            write_plain(out, *y, 0);
            out.push_str(", ");
            write_plain(out, *x, 0);
            out.push(')');
        }
    }
}

/// Writes `c * rest` (with `c >= 0`) as a product with numerator and denominator.
fn write_product(out: &mut String, c: Rational, rest: Expr, outer: u8) {
    let factors: Vec<Expr> = match rest.node() {
        Node::Mul(fs) => fs.to_vec(),
        _ if rest.is_one() => Vec::new(),
        _ => vec![rest],
    };
    let mut num: Vec<Expr> = Vec::new();
    let mut den: Vec<Expr> = Vec::new();
    let mut float_lead: Option<f64> = None;
    for f in factors {
        if let Node::Float(b) = f.node() {
            float_lead = Some(b.value());
            continue;
        }
        let (b, x) = f.base_and_exp();
        match x.as_rational() {
            Some(r) if r.is_negative() => den.push(b.pow(Expr::rational(r.abs()))),
            _ => num.push(f),
        }
    }
    let num = print_order(&num);
    let den = print_order(&den);
    let cnum = Rational::int(c.numer());
    let cden = c.denom();
    let needs = outer > PREC_MUL;
    if needs {
        out.push('(');
    }
    let mut parts: Vec<String> = Vec::new();
    if let Some(v) = float_lead {
        parts.push(fmt_float(v));
    }
    if !cnum.is_one() || (num.is_empty() && float_lead.is_none()) {
        parts.push(cnum.to_string());
    }
    for f in &num {
        let mut s = String::new();
        write_plain(&mut s, *f, PREC_MUL);
        parts.push(s);
    }
    out.push_str(&parts.join("*"));
    let den_count = den.len() + usize::from(cden != 1);
    if den_count > 0 {
        out.push('/');
        if den_count > 1 {
            out.push('(');
        }
        let mut dparts: Vec<String> = Vec::new();
        if cden != 1 {
            dparts.push(cden.to_string());
        }
        for f in &den {
            let mut s = String::new();
            write_plain(&mut s, *f, if den_count > 1 { PREC_MUL } else { PREC_POW });
            dparts.push(s);
        }
        out.push_str(&dparts.join("*"));
        if den_count > 1 {
            out.push(')');
        }
    }
    if needs {
        out.push(')');
    }
}

impl fmt::Display for Expr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut s = String::new();
        write_plain(&mut s, *self, 0);
        f.write_str(&s)
    }
}

const GREEK: [&str; 24] = [
    "alpha", "beta", "gamma", "delta", "epsilon", "zeta", "eta", "theta", "iota", "kappa",
    "lambda", "mu", "nu", "xi", "omicron", "pi", "rho", "sigma", "tau", "upsilon", "phi", "chi",
    "psi", "omega",
];

/// LaTeX for a symbol name: `theta'` -> `\dot{\theta}`, `J2h` -> `J_{2h}`,
/// `eta_m` -> `\eta_{m}`.
pub fn latex_symbol(name: &str) -> String {
    let primes = name.len() - name.trim_end_matches('\'').len();
    let base = name.trim_end_matches('\'');
    let (head, sub) = match base.find('_') {
        Some(i) => (&base[..i], Some(base[i + 1..].to_string())),
        None => {
            // letters followed by a digit-led suffix: J2h -> J_{2h}
            match base.find(|c: char| c.is_ascii_digit()) {
                Some(i) if i > 0 => (&base[..i], Some(base[i..].to_string())),
                _ => (base, None),
            }
        }
    };
    let lower = head.to_ascii_lowercase();
    let mut h = if GREEK.contains(&head) || (GREEK.contains(&lower.as_str()) && head.len() > 1) {
        let mut g = head.to_string();
        if head.chars().next().is_some_and(|c| c.is_uppercase()) {
            g = format!("{}{}", &head[..1], &head[1..]);
        }
        format!("\\{g}")
    } else if head.len() > 1 {
        format!("\\mathrm{{{head}}}")
    } else {
        head.to_string()
    };
    if let Some(s) = sub {
        h = format!("{h}_{{{s}}}");
    }
    match primes {
        0 => h,
        1 => format!("\\dot{{{h}}}"),
        2 => format!("\\ddot{{{h}}}"),
        n => format!("{h}^{{({n})}}"),
    }
}

fn write_latex(out: &mut String, e: Expr, outer: u8) {
    match e.node() {
        Node::Rational(r) => {
            if r.is_integer() {
                if r.is_negative() && outer > PREC_ADD {
                    let _ = write!(out, "\\left({r}\\right)");
                } else {
                    let _ = write!(out, "{r}");
                }
            } else {
                let sign = if r.is_negative() { "-" } else { "" };
                let _ = write!(out, "{sign}\\frac{{{}}}{{{}}}", r.numer().abs(), r.denom());
            }
        }
        Node::Float(b) => out.push_str(&fmt_float(b.value())),
        Node::Symbol(s) | Node::Named(s, _) => out.push_str(&latex_symbol(s.name())),
        Node::Add(terms) => write_sum(
            out,
            terms,
            outer,
            ("\\left(", "\\right)"),
            write_latex,
            write_latex_product,
        ),
        Node::Mul(_) => {
            let (c, rest) = e.coeff_and_rest();
            if c.is_negative() {
                out.push('-');
                write_latex_product(out, c.abs(), rest, PREC_MUL);
            } else {
                write_latex_product(out, c, rest, outer);
            }
        }
        Node::Pow(b, x) => {
            if let Some(r) = x.as_rational() {
                if r.is_negative() {
                    write_latex_product(out, Rational::ONE, e, outer);
                    return;
                }
                if r == Rational::new(1, 2).unwrap() {
                    out.push_str("\\sqrt{");
                    write_latex(out, *b, 0);
                    out.push('}');
                    return;
                }
            }
            if let Node::Func(f, arg) = b.node() {
                // sin^2(x) style
                let _ = write!(out, "\\{}^{{", f.name());
                write_latex(out, *x, 0);
                out.push_str("}\\left(");
                write_latex(out, *arg, 0);
                out.push_str("\\right)");
                return;
            }
            write_latex(out, *b, PREC_POW + 1);
            out.push_str("^{");
            write_latex(out, *x, 0);
            out.push('}');
        }
        Node::Func(f, x) => {
            let name = match f {
                super::expr::Func::Abs => {
                    out.push_str("\\left|");
                    write_latex(out, *x, 0);
                    out.push_str("\\right|");
                    return;
                }
                super::expr::Func::Sign => "\\operatorname{sign}",
                super::expr::Func::Sin => "\\sin",
                super::expr::Func::Cos => "\\cos",
                super::expr::Func::Tan => "\\tan",
                super::expr::Func::Exp => "\\exp",
                super::expr::Func::Ln => "\\ln",
                super::expr::Func::Tanh => "\\tanh",
            };
            out.push_str(name);
            out.push_str("\\left(");
            write_latex(out, *x, 0);
            out.push_str("\\right)");
        }
        Node::Atan2(y, x) => {
            out.push_str("\\operatorname{atan2}\\left(");
            write_latex(out, *y, 0);
            out.push_str(", ");
            write_latex(out, *x, 0);
            out.push_str("\\right)");
        }
    }
}

fn write_latex_product(out: &mut String, c: Rational, rest: Expr, outer: u8) {
    let factors: Vec<Expr> = match rest.node() {
        Node::Mul(fs) => fs.to_vec(),
        _ if rest.is_one() => Vec::new(),
        _ => vec![rest],
    };
    let mut num = Vec::new();
    let mut den = Vec::new();
    for f in factors {
        let (b, x) = f.base_and_exp();
        match x.as_rational() {
            Some(r) if r.is_negative() => den.push(b.pow(Expr::rational(r.abs()))),
            _ => num.push(f),
        }
    }
    let num = print_order(&num);
    let den = print_order(&den);
    let needs = outer > PREC_MUL && (num.len() + den.len() > 1);
    if needs {
        out.push_str("\\left(");
    }
    let mut ntext = String::new();
    if c.numer() != 1 || num.is_empty() {
        let _ = write!(ntext, "{}", c.numer());
    }
    for (i, f) in num.iter().enumerate() {
        if i > 0 || !ntext.is_empty() {
            ntext.push(' ');
        }
        write_latex(&mut ntext, *f, PREC_MUL);
    }
    if den.is_empty() && c.denom() == 1 {
        out.push_str(&ntext);
    } else {
        let mut dtext = String::new();
        if c.denom() != 1 {
            let _ = write!(dtext, "{}", c.denom());
        }
        for (i, f) in den.iter().enumerate() {
            if i > 0 || !dtext.is_empty() {
                dtext.push(' ');
            }
            write_latex(&mut dtext, *f, PREC_MUL);
        }
        let _ = write!(out, "\\frac{{{ntext}}}{{{dtext}}}");
    }
    if needs {
        out.push_str("\\right)");
    }
}

impl Expr {
    /// LaTeX source for this expression.
    pub fn to_latex(self) -> String {
        let mut s = String::new();
        write_latex(&mut s, self, 0);
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prints_like_a_person() {
        let j = Expr::sym("J2h");
        let a = Expr::sym("alpha");
        let td = Expr::sym("theta'");
        let e = j * a.sin() * a.cos() * td.powi(2);
        assert_eq!(e.to_string(), "J2h*sin(alpha)*cos(alpha)*theta'^2");
        let x = Expr::sym("x");
        let y = Expr::sym("y");
        assert_eq!((x - y).to_string(), "x - y");
        assert_eq!((x / (2 * y)).to_string(), "x/(2*y)");
        assert_eq!((-x * y).to_string(), "-x*y");
        assert_eq!((x + y).powi(2).to_string(), "(x + y)^2");
        assert_eq!((Expr::frac(1, 2) * x).to_string(), "x/2");
        assert_eq!(x.sqrt().to_string(), "sqrt(x)");
        assert_eq!((x - (-y).sin()).to_string(), "x + sin(y)");
    }

    #[test]
    fn latex() {
        let e = Expr::sym("J2h") * Expr::sym("alpha").sin().powi(2) * Expr::sym("theta'");
        assert_eq!(
            e.to_latex(),
            "J_{2h} \\sin^{2}\\left(\\alpha\\right) \\dot{\\theta}"
        );
        assert_eq!(latex_symbol("eta_m"), "\\eta_{m}");
    }
}
