//! Print the model file of an n-link planar pendulum, in the canonical
//! layout of `plantc fmt` (as `models/chain4.plant` and `chain10.plant`):
//! `cargo run -p plantc-derive --example chain_model -- 10 > chain10.plant`.

fn main() {
    let n: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(4);
    let text = plantc_derive::model::n_link_chain_source(n);
    // the generator lays its tables out by hand; the formatter aligns them
    print!(
        "{}",
        plantc_derive::lang::format::format(&text).unwrap_or(text)
    );
}
