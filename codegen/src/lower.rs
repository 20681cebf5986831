//! Translation of a derive [`Tape`] into straight-line Rust statements.
//!
//! The tape already gives us what the emitted code needs: every DAG node is
//! lowered once (common subexpressions across all outputs of one function),
//! `sin`/`cos` of the same argument are fused, integer powers are
//! multiplication chains, negative powers divisions. The tape reuses scratch
//! slots; here every instruction gets a fresh `let` binding instead (SSA), and
//! constants and inputs are inlined as literals and place expressions.

use proc_macro2::{Ident, Literal, Span, TokenStream};
use quote::{format_ident, quote};

use plantc_derive::sym::{Expr, Instr, Symbol, Tape};

use crate::Error;

/// An `f64` literal (shortest round-trip representation), parenthesised when negative.
pub(crate) fn lit(x: f64) -> Result<TokenStream, Error> {
    if !x.is_finite() {
        return Err(Error::Generate(format!(
            "a constant of the generated code is not finite ({x})"
        )));
    }
    let mag = format!("{:?}", x.abs());
    let l: Literal = mag
        .parse()
        .map_err(|_| Error::Generate(format!("cannot form a literal from {mag}")))?;
    Ok(if x.is_sign_negative() && x != 0.0 {
        quote!(-#l)
    } else {
        quote!(#l)
    })
}

/// An identifier for a model name (raw identifier for Rust keywords).
pub(crate) fn ident(name: &str) -> Ident {
    let clean: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    if syn::parse_str::<Ident>(&clean).is_ok() {
        Ident::new(&clean, Span::call_site())
    } else {
        Ident::new_raw(&clean, Span::call_site())
    }
}

/// Statements computing a set of outputs, and one expression per output.
pub(crate) struct Lowered {
    pub stmts: Vec<TokenStream>,
    pub outputs: Vec<TokenStream>,
}

/// Lower `outputs` (functions of `inputs`) to statements. `bind` gives the
/// Rust place expression of each input symbol. Locals are named `{prefix}{k}`.
pub(crate) fn lower(
    outputs: &[Expr],
    inputs: &[(Symbol, TokenStream)],
    prefix: &str,
) -> Result<Lowered, Error> {
    let syms: Vec<Symbol> = inputs.iter().map(|(s, _)| *s).collect();
    let tape = Tape::compile(outputs, &syms).map_err(|e| Error::Generate(e.to_string()))?;
    let mut slot: Vec<Option<TokenStream>> = vec![None; tape.scratch_len()];
    let mut stmts = Vec::new();
    let mut counter = 0usize;
    let mut fresh = || {
        let id = format_ident!("{}{}", prefix, counter);
        counter += 1;
        id
    };
    let get = |slot: &Vec<Option<TokenStream>>, s: u32| -> TokenStream {
        slot[s as usize].clone().expect("tape reads an unset slot")
    };
    for ins in tape.instructions() {
        match *ins {
            Instr::Const { dst, value } => slot[dst as usize] = Some(lit(value)?),
            Instr::Input { dst, index } => {
                slot[dst as usize] = Some(inputs[index as usize].1.clone())
            }
            Instr::SinCos {
                sin_dst,
                cos_dst,
                a,
            } => {
                let a = get(&slot, a);
                let s = fresh();
                let c = fresh();
                stmts.push(quote!(let (#s, #c) = math::sin_cos(#a);));
                slot[sin_dst as usize] = Some(quote!(#s));
                slot[cos_dst as usize] = Some(quote!(#c));
            }
            _ => {
                let (dst, rhs) = match *ins {
                    Instr::Add { dst, a, b } => {
                        let (a, b) = (get(&slot, a), get(&slot, b));
                        (dst, quote!(#a + #b))
                    }
                    Instr::Sub { dst, a, b } => {
                        let (a, b) = (get(&slot, a), get(&slot, b));
                        (dst, quote!(#a - #b))
                    }
                    Instr::Mul { dst, a, b } => {
                        let (a, b) = (get(&slot, a), get(&slot, b));
                        (dst, quote!(#a * #b))
                    }
                    Instr::Div { dst, a, b } => {
                        let (a, b) = (get(&slot, a), get(&slot, b));
                        (dst, quote!(#a / #b))
                    }
                    Instr::Neg { dst, a } => {
                        let a = get(&slot, a);
                        (dst, quote!(-#a))
                    }
                    Instr::Sqrt { dst, a } => {
                        let a = get(&slot, a);
                        (dst, quote!(math::sqrt(#a)))
                    }
                    Instr::Pow { dst, a, b } => {
                        let (a, b) = (get(&slot, a), get(&slot, b));
                        (dst, quote!(math::powf(#a, #b)))
                    }
                    Instr::Atan2 { dst, y, x } => {
                        let (y, x) = (get(&slot, y), get(&slot, x));
                        (dst, quote!(math::atan2(#y, #x)))
                    }
                    Instr::Func { dst, f, a } => {
                        let a = get(&slot, a);
                        let name = format_ident!("{}", f.name());
                        (dst, quote!(math::#name(#a)))
                    }
                    _ => unreachable!(),
                };
                let v = fresh();
                stmts.push(quote!(let #v = #rhs;));
                slot[dst as usize] = Some(quote!(#v));
            }
        }
    }
    let outputs = tape.output_slots().iter().map(|s| get(&slot, *s)).collect();
    Ok(Lowered { stmts, outputs })
}

/// Statements solving `M y = b` for several right-hand sides with an unrolled
/// LDL^T factorisation of the symmetric positive definite `M` (no square
/// roots, one division per pivot). `m[i][j]` for `j <= i` are the entries of
/// the lower triangle. Each solution is bound as `{name}{i}` for `name` in
/// `sol_names`; `None` right-hand-side entries are zero.
pub(crate) fn ldl_solve(
    m: &[Vec<TokenStream>],
    rhs: &[Vec<Option<TokenStream>>],
    sol_names: &[String],
) -> Vec<TokenStream> {
    let n = m.len();
    let mut st = Vec::new();
    let l = |i: usize, j: usize| format_ident!("ldl_l{}_{}", i, j);
    let dinv = |j: usize| format_ident!("ldl_dinv{}", j);
    // e_jk = L_jk d_k
    let e = |j: usize, k: usize| format_ident!("ldl_e{}_{}", j, k);
    for j in 0..n {
        let mut dj = m[j][j].clone();
        for k in 0..j {
            let (ljk, ejk) = (l(j, k), e(j, k));
            dj = quote!(#dj - #ljk * #ejk);
        }
        let di = dinv(j);
        st.push(quote!(let #di = 1.0 / (#dj);));
        for i in j + 1..n {
            let mut v = m[i][j].clone();
            for k in 0..j {
                let (lik, ejk) = (l(i, k), e(j, k));
                v = quote!(#v - #lik * #ejk);
            }
            let (eij, lij) = (e(i, j), l(i, j));
            st.push(quote!(let #eij = #v;));
            st.push(quote!(let #lij = #eij * #di;));
        }
    }
    for (b, name) in rhs.iter().zip(sol_names) {
        let z = |i: usize| format_ident!("{}z{}", name, i);
        let y = |i: usize| format_ident!("{}{}", name, i);
        for i in 0..n {
            let mut v = match &b[i] {
                Some(t) => t.clone(),
                None => quote!(0.0),
            };
            for k in 0..i {
                let (lik, zk) = (l(i, k), z(k));
                v = quote!(#v - #lik * #zk);
            }
            let zi = z(i);
            st.push(quote!(let #zi = #v;));
        }
        for i in (0..n).rev() {
            let (zi, di) = (z(i), dinv(i));
            let mut v = quote!(#zi * #di);
            for k in i + 1..n {
                let (lki, yk) = (l(k, i), y(k));
                v = quote!(#v - #lki * #yk);
            }
            let yi = y(i);
            st.push(quote!(let #yi = #v;));
        }
    }
    st
}
