//! Small symbolic matrix helpers: determinant and adjugate by cofactor
//! expansion with memoised minors (fine for the few degrees of freedom of a
//! lab rig; the mass matrix is never inverted for numeric evaluation).

use std::collections::HashMap;

use crate::sym::Expr;

/// Determinant of the square symbolic matrix `m`.
pub fn determinant(m: &[Vec<Expr>]) -> Expr {
    let n = m.len();
    if n == 0 {
        return Expr::one();
    }
    let rows: Vec<usize> = (0..n).collect();
    let cols: Vec<usize> = (0..n).collect();
    let mut memo = HashMap::new();
    minor_det(m, &rows, &cols, &mut memo)
}

fn minor_det(
    m: &[Vec<Expr>],
    rows: &[usize],
    cols: &[usize],
    memo: &mut HashMap<(Vec<usize>, Vec<usize>), Expr>,
) -> Expr {
    if rows.len() == 1 {
        return m[rows[0]][cols[0]];
    }
    let key = (rows.to_vec(), cols.to_vec());
    if let Some(&d) = memo.get(&key) {
        return d;
    }
    let r0 = rows[0];
    let sub_rows = &rows[1..];
    let mut terms = Vec::with_capacity(cols.len());
    for (k, &c) in cols.iter().enumerate() {
        let a = m[r0][c];
        if a.is_zero() {
            continue;
        }
        let sub_cols: Vec<usize> = cols.iter().copied().filter(|&x| x != c).collect();
        let d = minor_det(m, sub_rows, &sub_cols, memo);
        let t = a * d;
        terms.push(if k % 2 == 0 { t } else { -t });
    }
    let d = Expr::add_all(terms);
    memo.insert(key, d);
    d
}

/// Adjugate (transposed cofactor matrix): `m * adj(m) = det(m) I`.
pub fn adjugate(m: &[Vec<Expr>]) -> Vec<Vec<Expr>> {
    let n = m.len();
    if n == 1 {
        return vec![vec![Expr::one()]];
    }
    let mut memo = HashMap::new();
    let mut adj = vec![vec![Expr::zero(); n]; n];
    for i in 0..n {
        for (j, adj_j) in adj.iter_mut().enumerate() {
            let rows: Vec<usize> = (0..n).filter(|&r| r != i).collect();
            let cols: Vec<usize> = (0..n).filter(|&c| c != j).collect();
            let d = minor_det(m, &rows, &cols, &mut memo);
            // cofactor C_ij goes to adj[j][i]
            adj_j[i] = if (i + j) % 2 == 0 { d } else { -d };
        }
    }
    adj
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_by_two() {
        let (a, b, c, d) = (
            Expr::sym("a"),
            Expr::sym("b"),
            Expr::sym("c"),
            Expr::sym("d"),
        );
        let m = vec![vec![a, b], vec![c, d]];
        assert_eq!(determinant(&m), a * d - b * c);
        let adj = adjugate(&m);
        assert_eq!(adj, vec![vec![d, -b], vec![-c, a]]);
    }
}
