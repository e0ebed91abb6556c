fn main() {
    let mut p = strip::StripParams::default();
    if let Some(h) = std::env::args().nth(1) {
        p.element_m = h.parse::<f64>().unwrap() * 1e-3;
    }
    if let Some(nu) = std::env::args().nth(2) {
        p.poisson = nu.parse().unwrap();
    }
    let (r, _) = strip::report::make_report(&p).unwrap();
    println!("{}", r.table());
}
