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
