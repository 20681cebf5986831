//! The `plantc` command line (thin: parsing and printing; the work is in the
//! library crates).

fn main() {
    let code = plantc::run(
        std::env::args_os(),
        &mut std::io::stdout(),
        &mut std::io::stderr(),
    );
    std::process::exit(code);
}
