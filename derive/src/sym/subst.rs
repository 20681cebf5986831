//! Substitution of subexpressions.

use std::collections::HashMap;

use super::fxhash::FxHashMap;

use super::expr::{Expr, Node, Symbol};

/// Replace every occurrence of a key of `map` (any subexpression, usually a
/// symbol) by its value, rebuilding the DAG bottom-up (memoised).
pub fn substitute(e: Expr, map: &HashMap<Expr, Expr>) -> Expr {
    let mut memo = FxHashMap::default();
    subst_memo(e, map, &mut memo)
}

/// Replace symbols by expressions.
pub fn substitute_symbols(e: Expr, map: &HashMap<Symbol, Expr>) -> Expr {
    let m: HashMap<Expr, Expr> = map.iter().map(|(k, v)| (Expr::symbol(*k), *v)).collect();
    substitute(e, &m)
}

/// [`substitute_symbols`] of several expressions sharing one memo (their
/// common subexpressions are rebuilt once).
pub fn substitute_symbols_all(es: &[Expr], map: &HashMap<Symbol, Expr>) -> Vec<Expr> {
    let m: HashMap<Expr, Expr> = map.iter().map(|(k, v)| (Expr::symbol(*k), *v)).collect();
    let mut memo = FxHashMap::default();
    es.iter().map(|e| subst_memo(*e, &m, &mut memo)).collect()
}

fn subst_memo(e: Expr, map: &HashMap<Expr, Expr>, memo: &mut FxHashMap<Expr, Expr>) -> Expr {
    if let Some(&v) = map.get(&e) {
        return v;
    }
    if let Some(&v) = memo.get(&e) {
        return v;
    }
    let r = match e.node() {
        Node::Rational(_) | Node::Float(_) | Node::Symbol(_) => e,
        Node::Add(ts) => Expr::add_all(ts.iter().map(|t| subst_memo(*t, map, memo))),
        Node::Mul(fs) => Expr::mul_all(fs.iter().map(|f| subst_memo(*f, map, memo))),
        Node::Pow(b, p) => subst_memo(*b, map, memo).pow(subst_memo(*p, map, memo)),
        Node::Func(f, x) => Expr::apply(*f, subst_memo(*x, map, memo)),
        Node::Atan2(y, x) => Expr::atan2(subst_memo(*y, map, memo), subst_memo(*x, map, memo)),
        Node::Named(s, d) => {
            let d2 = subst_memo(*d, map, memo);
            if d2 == *d {
                e
            } else {
                Expr::named(s.name(), d2)
            }
        }
    };
    memo.insert(e, r);
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn substitutes_and_resimplifies() {
        let x = Expr::sym("x");
        let y = Expr::sym("y");
        let e = x.sin() + y * x;
        let mut m = HashMap::new();
        m.insert(x, Expr::zero());
        assert_eq!(substitute(e, &m), Expr::zero());
    }
}
