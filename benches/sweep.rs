fn main() { eprintln!("sweep benchmark: not written yet"); }
