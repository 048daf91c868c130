fn main() { eprintln!("arm benchmark: not written yet"); }
