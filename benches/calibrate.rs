fn main() { eprintln!("calibrate benchmark: not written yet"); }
