fn main() {
    println!("plantc");
}
