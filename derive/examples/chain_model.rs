//! Print the model file of an n-link planar pendulum:
//! `cargo run -p plantc-derive --example chain_model -- 10 > chain10.plant`.

fn main() {
    let n: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(4);
    print!("{}", plantc_derive::model::n_link_chain_source(n));
}
