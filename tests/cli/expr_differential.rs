//! Differential test of scene expressions against Python: random expression trees (seeded
//! PRNG) are printed in the scene syntax with only the parentheses that the documented
//! precedence table (docs/expressions.md) needs, parsed and evaluated by `Expr`, and
//! translated, fully parenthesized, to Python (`if(c, a, b)` as `a if c != 0 else b`), where NumPy float64 scalars do + − × ÷ (IEEE,
//! division by zero gives ±inf or NaN) and the C math library, called through ctypes, does
//! `^` (pow), `%` (fmod) and the functions: the very functions Rust's std calls, so most
//! values agree bit for bit. The truth-value and NaN rules of the grammar are written out
//! again in Python. A mismatch is a difference in NaN-ness or in an infinity, or finite values
//! that differ by more than 4 ulps of the larger (relative 4·2⁻⁵²).
//!
//! An expression `Expr` refuses must have a part without variables that Python finds
//! non-finite (the grammar refuses those on purpose); expressions broken on purpose (a unit
//! suffix, a chained comparison, `log`, `**`, `z` in 2D, a missing parenthesis) must be
//! refused naming the key.
//!
//! `EXPR_DIFF_SEED` (default: from the clock; printed) and `EXPR_DIFF_COUNT` (default 300)
//! choose the expressions. Without python3 and NumPy the test is skipped with a note, except
//! in CI.

use std::fmt::Write as _;
use std::process::Command;
use viscontact::expr::{Expr, Point};

use crate::common;
use common::SplitMix;

/// An expression tree; `Bin` and `Un` carry the scene operator.
enum Node {
    Num(f64),
    Name(&'static str),
    Un(&'static str, Box<Node>),
    Bin(&'static str, Box<Node>, Box<Node>),
    Call(&'static str, Vec<Node>),
}

const VARS: [&str; 5] = ["x", "y", "z", "t", "s"];
const BINARY: [&str; 14] = [
    "+", "-", "*", "/", "%", "^", "<", "<=", ">", ">=", "==", "!=", "&&", "||",
];
const FUNCS: [(&str, usize); 26] = [
    ("abs", 1),
    ("sqrt", 1),
    ("exp", 1),
    ("ln", 1),
    ("log10", 1),
    ("log2", 1),
    ("sin", 1),
    ("cos", 1),
    ("tan", 1),
    ("asin", 1),
    ("acos", 1),
    ("atan", 1),
    ("sinh", 1),
    ("cosh", 1),
    ("tanh", 1),
    ("floor", 1),
    ("ceil", 1),
    ("round", 1),
    ("trunc", 1),
    ("sign", 1),
    ("pow", 2),
    ("atan2", 2),
    ("min", 2),
    ("max", 3),
    ("if", 3),
    ("min", 3),
];

fn tree(r: &mut SplitMix, depth: usize) -> Node {
    if depth == 0 || r.unit() < 0.25 {
        return match r.below(10) {
            0..=3 => Node::Num(r.pick(&[
                0.0, 1.0, 2.0, 0.5, 3.0, 10.0, 0.1, 1e-3, 2.5, 7.0, 1e-15, 1e10, 0.2, 4.0,
            ])),
            4 => Node::Num((r.unit() * 1000.0).round() / 100.0),
            5 => Node::Name(r.pick(&["pi", "e"])),
            _ => Node::Name(r.pick(&VARS)),
        };
    }
    let d = depth - 1;
    match r.below(10) {
        0..=4 => {
            // The arithmetic operators (the first 6) more often than the others.
            let ops = 6.max(r.below(BINARY.len() + 1));
            let op = r.pick(&BINARY[..ops]);
            Node::Bin(op, Box::new(tree(r, d)), Box::new(tree(r, d)))
        }
        5 => Node::Un(r.pick(&["-", "-", "!"]), Box::new(tree(r, d))),
        _ => {
            let (f, n) = r.pick(&FUNCS);
            Node::Call(f, (0..n).map(|_| tree(r, d)).collect())
        }
    }
}

/// The precedence level of a node (docs/expressions.md): || 1, && 2, comparisons 3, + − 4,
/// * / % 5, unary 6, ^ 7, operands 8.
fn level(n: &Node) -> u8 {
    match n {
        Node::Bin(op, ..) => match *op {
            "||" => 1,
            "&&" => 2,
            "+" | "-" => 4,
            "*" | "/" | "%" => 5,
            "^" => 7,
            _ => 3,
        },
        Node::Un(..) => 6,
        _ => 8,
    }
}

/// The scene syntax, with parentheses where the precedence table needs them (and now and
/// then where it does not).
fn scene(n: &Node, r: &mut SplitMix) -> String {
    let wrap = |c: &Node, need: bool, r: &mut SplitMix| {
        let s = scene(c, r);
        if need || r.below(20) == 0 {
            format!("({s})")
        } else {
            s
        }
    };
    match n {
        Node::Num(v) => format!("{v:?}"),
        Node::Name(s) => s.to_string(),
        Node::Un(op, c) => format!("{op}{}", wrap(c, level(c) < 6, r)),
        Node::Bin(op, a, b) => {
            let l = level(n);
            let (need_a, need_b) = match l {
                3 => (level(a) <= 3, level(b) <= 3),
                7 => (level(a) < 8, level(b) < 6),
                _ => (level(a) < l, level(b) <= l),
            };
            let sp = r.pick(&["", " "]);
            format!("{}{sp}{op}{sp}{}", wrap(a, need_a, r), wrap(b, need_b, r))
        }
        Node::Call(f, args) => {
            let args: Vec<String> = args.iter().map(|a| scene(a, r)).collect();
            format!("{f}({})", args.join(", "))
        }
    }
}

/// The Python translation, fully parenthesized.
fn python(n: &Node) -> String {
    match n {
        Node::Num(v) => format!("F({v:?})"),
        Node::Name("pi") => "F(math.pi)".into(),
        Node::Name("e") => "F(math.e)".into(),
        Node::Name(s) => s.to_string(),
        Node::Un("-", c) => format!("(-{})", python(c)),
        Node::Un(_, c) => format!("lnot({})", python(c)),
        Node::Bin(op @ ("+" | "-" | "*" | "/"), a, b) => {
            format!("({} {op} {})", python(a), python(b))
        }
        Node::Bin(op, a, b) => {
            let f = match *op {
                "%" => "C.fmod",
                "^" => "C.pow",
                "<" => "lt",
                "<=" => "le",
                ">" => "gt",
                ">=" => "ge",
                "==" => "eq",
                "!=" => "ne",
                "&&" => "land",
                _ => "lor",
            };
            format!("{f}({}, {})", python(a), python(b))
        }
        Node::Call("if", args) => {
            let [c, a, b] = &args[..] else { unreachable!() };
            let (c, a, b) = (python(c), python(a), python(b));
            format!("iff({c}, {a}, {b})")
        }
        Node::Call(f, args) => {
            let args: Vec<String> = args.iter().map(python).collect();
            let f = match *f {
                "min" => "nmin",
                "max" => "nmax",
                "sign" => "sign",
                "abs" => "C.fabs",
                "ln" => "C.log",
                f => return format!("C.{f}({})", args.join(", ")),
            };
            format!("{f}({})", args.join(", "))
        }
    }
}

/// The Python translations of the parts that use no variable.
fn constant_parts(n: &Node, out: &mut Vec<String>) -> bool {
    let constant = match n {
        Node::Num(_) => true,
        Node::Name(s) => matches!(*s, "pi" | "e"),
        Node::Un(_, c) => constant_parts(c, out),
        Node::Bin(_, a, b) => constant_parts(a, out) & constant_parts(b, out),
        Node::Call(_, args) => args
            .iter()
            .fold(true, |all, a| constant_parts(a, out) & all),
    };
    if constant {
        out.push(python(n));
    }
    constant
}

const PRELUDE: &str = r#"
import ctypes, ctypes.util, math, sys
import numpy as np
np.seterr(all="ignore")
F = np.float64
NAN = F("nan")
LIBM = ctypes.CDLL(ctypes.util.find_library("m"))
class C: pass
def libm(name, n):
    f = getattr(LIBM, name)
    f.restype = ctypes.c_double
    f.argtypes = [ctypes.c_double] * n
    setattr(C, name, staticmethod(lambda *a: F(f(*[float(v) for v in a]))))
for name in ["fabs", "sqrt", "exp", "log", "log10", "log2", "sin", "cos", "tan", "asin",
             "acos", "atan", "sinh", "cosh", "tanh", "floor", "ceil", "round", "trunc"]:
    libm(name, 1)
for name in ["pow", "atan2", "fmod"]:
    libm(name, 2)
isnan = math.isnan
def truth(a, b, v):
    return NAN if isnan(a) or isnan(b) else F(1.0 if v else 0.0)
def lt(a, b): return truth(a, b, a < b)
def le(a, b): return truth(a, b, a <= b)
def gt(a, b): return truth(a, b, a > b)
def ge(a, b): return truth(a, b, a >= b)
def eq(a, b): return truth(a, b, a == b)
def ne(a, b): return truth(a, b, a != b)
def land(a, b): return truth(a, b, a != 0 and b != 0)
def lor(a, b): return truth(a, b, a != 0 or b != 0)
def lnot(a): return truth(a, a, a == 0)
def nmin(*a): return NAN if any(isnan(v) for v in a) else min(a)
def nmax(*a): return NAN if any(isnan(v) for v in a) else max(a)
def sign(a): return NAN if isnan(a) else F(1.0 if a > 0 else -1.0 if a < 0 else 0.0)
def iff(c, a, b): return NAN if isnan(c) else (a if c != 0 else b)
def show(v): return repr(float(v))
for (f, consts, points) in CASES:
    bad = any(not math.isfinite(float(c())) for c in consts)
    vals = [show(f(*[F(v) for v in p])) for p in points]
    print(int(bad), *vals)
"#;

/// Values of the variables: ordinary, zero, ±1, large and small.
fn point(r: &mut SplitMix) -> [f64; 5] {
    std::array::from_fn(|_| match r.below(8) {
        0 => 0.0,
        1 => r.pick(&[1.0, -1.0, 0.5, 2.0]),
        2 => r.pick(&[1e3, -1e-3, 1e-300, 30.0]),
        _ => ((r.unit() * 6.0 - 3.0) * 1e4).round() / 1e4,
    })
}

/// Whether `a` (Rust) and `b` (Python) are equal (both NaN counts), agree within 4 ulps,
/// or neither.
#[derive(PartialEq)]
enum Agreement {
    Equal,
    Close,
    Mismatch,
}

fn agreement(a: f64, b: f64) -> Agreement {
    if a == b || (a.is_nan() && b.is_nan()) {
        Agreement::Equal
    } else if a.is_finite()
        && b.is_finite()
        && (a - b).abs() <= 4.0 * f64::EPSILON * a.abs().max(b.abs())
    {
        Agreement::Close
    } else {
        Agreement::Mismatch
    }
}

/// Whether python3 with NumPy runs; outside CI its absence skips the test.
fn have_python() -> bool {
    let probe = Command::new("python3")
        .args(["-c", "import numpy"])
        .output();
    let ok = probe.map(|o| o.status.success()).unwrap_or(false);
    assert!(
        ok || std::env::var_os("CI").is_none(),
        "python3 with numpy is required in CI"
    );
    ok
}

fn env_or(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// The broken variants of an accepted expression `e`, the variables each is parsed with and
/// a phrase its message must hold.
fn broken(e: &str) -> [(String, &'static [&'static str], &'static str); 6] {
    [
        (format!("{e} + 2k"), &VARS, "no unit suffixes"),
        (format!("({e}) < 1 < 2"), &VARS, "&&"),
        (format!("log({e})"), &VARS, "ln(x)"),
        (format!("({e}) ** 2"), &VARS, "a^b"),
        (format!("({e}"), &VARS, "')' is missing"),
        (
            format!("{e} + z"),
            &["x", "y", "t", "s"],
            "a 2D model has no z",
        ),
    ]
}

#[test]
fn expressions_agree_with_python() {
    if !have_python() {
        eprintln!("SKIPPED expressions_agree_with_python: python3 with numpy is not installed");
        return;
    }
    let seed = env_or("EXPR_DIFF_SEED", {
        let now = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH);
        now.map(|d| d.as_nanos() as u64).unwrap_or(1)
    });
    let count = env_or("EXPR_DIFF_COUNT", 300) as usize;
    println!("expr_differential: EXPR_DIFF_SEED={seed} EXPR_DIFF_COUNT={count}");
    let mut r = SplitMix(seed);
    let key = "load.traction[0].value[1]";
    let mut cases = String::from("CASES = [\n");
    let mut ours = Vec::new();
    let mut mismatches = Vec::new();
    let mut broken_refused = 0;
    for _ in 0..count {
        let depth = 1 + r.below(6);
        let node = tree(&mut r, depth);
        let text = scene(&node, &mut r);
        let points: Vec<[f64; 5]> = (0..3).map(|_| point(&mut r)).collect();
        let parsed = Expr::parse(&text, &VARS, key);
        let values: Option<Vec<f64>> = parsed.as_ref().ok().map(|e| {
            let at = |p: &[f64; 5]| Point {
                x: p[0],
                y: p[1],
                z: p[2],
                t: p[3],
                s: p[4],
            };
            points.iter().map(|p| e.eval(&at(p))).collect()
        });
        if values.is_some() {
            for (b, vars, phrase) in broken(&text) {
                match Expr::parse(&b, vars, key) {
                    Err(m) if m.to_string().contains(phrase) && m.to_string().contains(key) => {
                        broken_refused += 1
                    }
                    other => mismatches.push(format!("{b:?} gave {other:?}, not {phrase:?}")),
                }
            }
        }
        let mut consts = Vec::new();
        constant_parts(&node, &mut consts);
        let consts: Vec<String> = consts.iter().map(|c| format!("lambda: {c}")).collect();
        let points_py: Vec<String> = points.iter().map(|p| format!("{p:?}")).collect();
        writeln!(
            cases,
            "(lambda x, y, z, t, s: {}, [{}], [{}]),",
            python(&node),
            consts.join(", "),
            points_py.join(", ")
        )
        .unwrap();
        ours.push((text, parsed.err().map(|e| e.to_string()), values));
    }
    cases.push_str("]\n");
    let dir = tempfile::tempdir().unwrap();
    let script = dir.path().join("cases.py");
    std::fs::write(&script, cases + PRELUDE).unwrap();
    let out = Command::new("python3").arg(&script).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8(out.stdout).unwrap();
    let (mut equal, mut close, mut refused, mut finite) = (0, 0, 0, 0);
    for ((text, err, values), line) in ours.iter().zip(stdout.lines()) {
        let mut words = line.split(' ');
        let bad = words.next() == Some("1");
        let theirs: Vec<f64> = words.map(|w| w.parse().unwrap()).collect();
        match (err, values) {
            (Some(e), _) if bad && e.contains("without variables") => refused += 1,
            (Some(e), _) => mismatches.push(format!("{text:?} refused: {e}")),
            (None, _) if bad => mismatches.push(format!("{text:?} accepted, constant not finite")),
            (None, Some(values)) => {
                for (a, b) in values.iter().zip(&theirs) {
                    finite += usize::from(a.is_finite());
                    match agreement(*a, *b) {
                        Agreement::Equal => equal += 1,
                        Agreement::Close => close += 1,
                        Agreement::Mismatch => {
                            mismatches.push(format!("{text:?}: ours {a:e}, Python {b:e}"))
                        }
                    }
                }
            }
            (None, None) => unreachable!(),
        }
    }
    assert_eq!(
        stdout.lines().count(),
        ours.len(),
        "Python answered every expression"
    );
    println!(
        "{count} expressions: {refused} refused for a non-finite constant part (Python agrees); \
         values ({finite} finite): {equal} equal, {close} within 4 ulps; {broken_refused} broken variants \
         refused; {} mismatches",
        mismatches.len()
    );
    assert!(
        mismatches.is_empty(),
        "seed {seed}: {}",
        mismatches[..mismatches.len().min(10)].join("\n")
    );
}
