//! Evaluation speed of scene expressions: ns per evaluation of a few typical loads and
//! kernels (those of examples/*.toml and the tests), each evaluated at 10⁶ points, the
//! median of 5 repetitions. Also the time to parse a 1 MB expression.
//!
//!   cargo run --release --example bench_expr

use std::hint::black_box;
use std::time::Instant;
use viscontact::expr::{Expr, Point};

const CASES: [(&str, &[&str]); 6] = [
    ("-0.1*x*(2-x)*min(t, 0.2)", &["x", "y", "t"]),
    (
        "if(t <= 0.5, 0.01*(1-y)*t, 0.01*(1-y)*0.2)",
        &["x", "y", "t"],
    ),
    ("0.01 + 0.02*t + 0.01*sin(3*t)", &["x", "y", "t"]),
    ("0.5*exp(-5*s)/(1 + s)", &["s"]),
    ("0.2*(s+0.01)^(-0.5)", &["s"]),
    ("0.7*exp(-3*s) + 0.2*exp(-0.5*s)", &["s"]),
];

/// The median over 5 repetitions of the ns per call of `f` at 10⁶ points.
fn ns_per_eval(f: impl Fn(&Point) -> f64) -> f64 {
    const N: usize = 1_000_000;
    let mut times: Vec<f64> = (0..5)
        .map(|_| {
            let start = Instant::now();
            let mut sum = 0.0;
            for i in 0..N {
                let v = i as f64 * 1e-6;
                let p = Point {
                    x: v,
                    y: 1.0 - v,
                    z: 0.5,
                    t: v,
                    s: v,
                };
                sum += f(black_box(&p));
            }
            black_box(sum);
            start.elapsed().as_secs_f64() * 1e9 / N as f64
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[2]
}

fn main() {
    println!("{:<48} {:>12}", "expression", "ns/eval");
    for (src, vars) in CASES {
        let e = Expr::parse(src, vars, "bench").expect("a valid expression");
        println!("{src:<48} {:>12.1}", ns_per_eval(|p| e.eval(p)));
    }
    let big = "x+".repeat(500_000) + "x";
    let start = Instant::now();
    let e = Expr::parse(&big, &["x"], "bench").expect("a valid expression");
    println!(
        "parse of a {} byte sum: {:.3} s (value at x = 1: {})",
        big.len(),
        start.elapsed().as_secs_f64(),
        e.eval(&Point {
            x: 1.0,
            ..Point::default()
        })
    );
}
