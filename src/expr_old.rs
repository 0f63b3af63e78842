//! Scene expressions: loads f0(x, y, z, t), f2(x, y, z, t), F(x, y, z), μ(x, y, z) and a
//! relaxation kernel r(s), parsed once by `fasteval2` (MIT, maintained fork of fasteval;
//! every literal is an f64, so `1/2` is 0.5, not an integer division).
//!
//! fasteval's compiled form is 3× faster than its parse tree, but the compiler's constant
//! folding drops a folded product within 8ε of 1 and a folded sum within 8ε of 0, and NaN
//! counts as both: `0/0` compiled to the constant 1, `x + 0/0` to `x`, `-(0/0)` to −1, and
//! `1e-20 + 0*x` to 0 (fasteval2 2.1; `compiler_folds_nan_away` below pins that behaviour,
//! so an upgrade that fixes it shows). So every expression is checked when the scene is
//! read: each part of it (the whole, each parenthesized part, each function argument) is
//! compiled on its own and evaluated both ways at a few probe points. Where the parse tree
//! gives a value that is not finite and the compiled form does not, the expression holds a
//! constant that is not finite (`0/0`, `0*(1/0)`, `(0-0)/(1-1)`, or `x*0/0` inside a
//! chain) and is refused; where they differ otherwise (a tiny constant dropped), the
//! expression is evaluated from its parse tree, exactly as written. Every part that uses no
//! variable must be finite as well.
//!
//! Beyond fasteval's built-ins (`min`, `max`, `abs`, `sin`, …, `log(base, x)`, comparison and
//! `&&`/`||` operators) an expression may call `if(cond, a, b)`, `exp`, `ln`, `sqrt`, `pow`,
//! `tanh` and use the constants `pi` and `e`. Unknown variables and functions are refused when
//! the scene is read, not in the middle of a run.

use crate::{Error, Result};
use fasteval2::{Compiler, Evaler, ExpressionI, Instruction, Parser, Slab};

/// `source` with every unary minus whose operand is raised to a power wrapped around the
/// power: `-s^2` → `-(s^2)`, `exp(-(s/2)^0.5)` → `exp(-((s/2)^0.5))`, `2^-s^2` → `2^-(s^2)`.
/// fasteval binds a unary minus tighter than `^` (it reads `-s^2` as s², `-2^0.5` as NaN);
/// the convention of mathematics, and of every language users write kernels in (Python,
/// Julia, MATLAB, gmsh), is −(s²). Nothing else changes, so every other expression parses
/// exactly as fasteval reads it.
fn power_before_negation(source: &str) -> String {
    let b = source.as_bytes();
    let mut out = String::with_capacity(source.len() + 8);
    let mut i = 0;
    let mut last = None; // the last non-space byte copied
    while i < b.len() {
        let c = b[i];
        let unary = c == b'-' && last.is_none_or(|p: u8| b"(,+-*/^%<>=!&|".contains(&p));
        if unary {
            let start = skip_spaces(b, i + 1);
            let mut end = operand_end(b, start);
            let mut powered = false;
            loop {
                let j = skip_spaces(b, end);
                if j < b.len() && b[j] == b'^' && end > start {
                    let e = skip_spaces(b, j + 1);
                    // The exponent may carry its own sign: 2^-s^2 = 2^(−(s²)).
                    let e = if e < b.len() && (b[e] == b'-' || b[e] == b'+') {
                        skip_spaces(b, e + 1)
                    } else {
                        e
                    };
                    end = operand_end(b, e);
                    powered = true;
                } else {
                    break;
                }
            }
            if powered {
                out.push_str("-(");
                out.push_str(&power_before_negation(&source[i + 1..end]));
                out.push(')');
                last = Some(b')');
                i = end;
                continue;
            }
        }
        // Copy one whole character (a non-ASCII one is refused by the parser, by name).
        let next = (i + 1..=b.len())
            .find(|&j| source.is_char_boundary(j))
            .unwrap_or(b.len());
        out.push_str(&source[i..next]);
        if !c.is_ascii_whitespace() {
            last = Some(c);
        }
        i = next;
    }
    out
}

fn skip_spaces(b: &[u8], mut i: usize) -> usize {
    while i < b.len() && b[i].is_ascii_whitespace() {
        i += 1;
    }
    i
}

/// The end of the operand starting at `i`: a number (with its exponent, `1e-3`), a name
/// with its call arguments, a parenthesized group, or a signed operand.
fn operand_end(b: &[u8], i: usize) -> usize {
    let close = |mut j: usize| {
        let mut depth = 0usize;
        while j < b.len() {
            match b[j] {
                b'(' => depth += 1,
                b')' => {
                    depth -= 1;
                    if depth == 0 {
                        return j + 1;
                    }
                }
                _ => {}
            }
            j += 1;
        }
        j
    };
    match b.get(i) {
        None => i,
        Some(b'(') => close(i),
        Some(b'-' | b'+') => operand_end(b, skip_spaces(b, i + 1)),
        Some(c) if c.is_ascii_digit() || *c == b'.' => {
            let mut j = i;
            while j < b.len() && (b[j].is_ascii_digit() || b[j] == b'.') {
                j += 1;
            }
            if j < b.len() && (b[j] == b'e' || b[j] == b'E') {
                let mut k = j + 1;
                if k < b.len() && (b[k] == b'-' || b[k] == b'+') {
                    k += 1;
                }
                if k < b.len() && b[k].is_ascii_digit() {
                    j = k;
                    while j < b.len() && b[j].is_ascii_digit() {
                        j += 1;
                    }
                }
            }
            j
        }
        Some(c) if c.is_ascii_alphabetic() || *c == b'_' => {
            let mut j = i;
            while j < b.len() && (b[j].is_ascii_alphanumeric() || b[j] == b'_') {
                j += 1;
            }
            let k = skip_spaces(b, j);
            if k < b.len() && b[k] == b'(' {
                close(k)
            } else {
                j
            }
        }
        Some(_) => i,
    }
}

/// Values of the variables an expression may use.
#[derive(Clone, Copy, Debug, Default)]
pub struct Point {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub t: f64,
    pub s: f64,
}

/// A parsed expression of some of the variables x, y, z, t, s.
pub struct Expr {
    source: String,
    slab: Slab,
    root: ExpressionI,
    /// The compiled form, where it agrees with the parse tree (see the module doc).
    compiled: Option<Instruction>,
}

impl std::fmt::Debug for Expr {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Expr({:?})", self.source)
    }
}

/// The functions an expression may call besides fasteval's built-ins.
fn call(name: &str, args: &[f64]) -> Option<f64> {
    Some(match (name, args) {
        ("if", [c, a, b]) => {
            if *c != 0.0 {
                *a
            } else {
                *b
            }
        }
        ("exp", [a]) => a.exp(),
        ("ln", [a]) => a.ln(),
        ("sqrt", [a]) => a.sqrt(),
        ("tanh", [a]) => a.tanh(),
        ("pow", [a, b]) => a.powf(*b),
        ("pi", []) => std::f64::consts::PI,
        ("e", []) => std::f64::consts::E,
        _ => return None,
    })
}

/// True if `src` calls `print(`: the identifier print, then optional blanks and a '('.
fn uses_print(src: &str) -> bool {
    let b = src.as_bytes();
    let ident = |c: u8| c.is_ascii_alphanumeric() || c == b'_';
    src.match_indices("print").any(|(i, _)| {
        let before_ok = i == 0 || !ident(b[i - 1]);
        let rest = src[i + 5..].trim_start();
        before_ok && rest.starts_with('(')
    })
}

/// fasteval's parse errors in words a user can act on.
fn parse_error(e: &fasteval2::Error) -> String {
    use fasteval2::Error as E;
    match e {
        E::EofWhileParsing(_) | E::EOF => {
            "it ends too early (an operand or a closing parenthesis is missing)".into()
        }
        E::UnparsedTokensRemaining(rest) => format!("unexpected text at {rest:?}"),
        E::Expected(what) => format!("expected {what}"),
        E::ParseF64(s) => format!("{s:?} is not a number"),
        E::InvalidValue => "a value is missing or invalid".into(),
        E::TooLong | E::TooDeep => "it is too long or too deeply nested".into(),
        other => format!("{other:?}"),
    }
}

fn variable(name: &str, p: &Point) -> Option<f64> {
    match name {
        "x" => Some(p.x),
        "y" => Some(p.y),
        "z" => Some(p.z),
        "t" => Some(p.t),
        "s" => Some(p.s),
        _ => None,
    }
}

impl Expr {
    /// Parses `source`, allowing only the variables in `allowed`. `key` names the scene entry
    /// in error messages (e.g. `load.traction[0].value[1]`).
    pub fn parse(source: &str, allowed: &[&str], key: &str) -> Result<Expr> {
        // fasteval's print() writes to stderr at every evaluation: not a scene function.
        if uses_print(source) {
            return Err(Error::input(format!(
                "{key}: expression {source:?} calls print(), which is not available in scenes"
            )));
        }
        let mut slab = Slab::new();
        let parsed = Parser::new()
            .parse(&power_before_negation(source), &mut slab.ps)
            .map_err(|e| {
                Error::input(format!(
                    "{key}: cannot parse expression {source:?}: {}",
                    parse_error(&e)
                ))
            })?;
        // Evaluate once with a recording namespace: every variable and custom function the
        // expression reaches must be known (all call arguments are evaluated eagerly).
        let mut unknown: Option<String> = None;
        let probe = Point::default();
        let mut ns = |name: &str, args: Vec<f64>| -> Option<f64> {
            if args.is_empty() {
                if let Some(v) = variable(name, &probe) {
                    if allowed.contains(&name) {
                        return Some(v);
                    }
                    unknown.get_or_insert_with(|| format!("variable '{name}'"));
                    return Some(0.0);
                }
            }
            match call(name, &args) {
                Some(v) => Some(v),
                None => {
                    unknown.get_or_insert_with(|| {
                        if args.is_empty() {
                            format!("variable '{name}'")
                        } else {
                            format!("function '{name}' with {} argument(s)", args.len())
                        }
                    });
                    Some(0.0)
                }
            }
        };
        // Evaluation errors at the probe point (e.g. a division by zero gives inf, not an
        // error) are irrelevant here; only the names matter.
        let _ = parsed.from(&slab.ps).eval(&slab, &mut ns);
        if let Some(what) = unknown {
            return Err(Error::input(format!(
                "{key}: expression {source:?} uses unknown {what}; allowed variables: {}; \
                 functions: fasteval's built-ins (min, max, abs, sin, cos, log, ...) and \
                 if(c, a, b), exp, ln, sqrt, pow, tanh, pi, e",
                allowed.join(", ")
            )));
        }
        let refuse = |v: f64| {
            Error::input(format!(
                "{key}: expression {source:?} has a part without variables that evaluates to \
                 {v} (a division by zero, or a function outside its domain); write a finite \
                 value"
            ))
        };
        if let Some(v) = non_finite_constant(&slab) {
            return Err(refuse(v));
        }
        let exact = match folding_differs(&mut slab) {
            Some(Folding::DropsNonFinite(v)) => return Err(refuse(v)),
            Some(Folding::Inexact) => true,
            None => false,
        };
        let compiled = (!exact).then(|| {
            parsed
                .from(&slab.ps)
                .compile(&slab.ps, &mut slab.cs, &mut fasteval2::EmptyNamespace)
        });
        Ok(Expr {
            source: source.to_string(),
            slab,
            root: parsed,
            compiled,
        })
    }

    /// The value at `p`. Unknown names were refused by `parse`, so an evaluation error cannot
    /// occur; a NaN is returned if it ever did, and the caller's finiteness check reports it.
    pub fn eval(&self, p: &Point) -> f64 {
        let mut ns = |name: &str, args: Vec<f64>| -> Option<f64> {
            if args.is_empty() {
                if let Some(v) = variable(name, p) {
                    return Some(v);
                }
            }
            call(name, &args)
        };
        match &self.compiled {
            Some(c) => c.eval(&self.slab, &mut ns),
            None => self.root.from(&self.slab.ps).eval(&self.slab, &mut ns),
        }
        .unwrap_or(f64::NAN)
    }

    pub fn source(&self) -> &str {
        &self.source
    }
}

/// How fasteval's compiled form of some part of an expression differs from its parse tree.
enum Folding {
    /// The parse tree gives this non-finite value where the compiled form does not.
    DropsNonFinite(f64),
    /// Some other difference (a tiny constant dropped).
    Inexact,
}

/// Compiles every part of the expression on its own (into the slab's compile area; the
/// instructions of the parts are never used) and compares it with the parse tree at probe
/// points where every variable takes one of a few unremarkable values.
fn folding_differs(slab: &mut Slab) -> Option<Folding> {
    const PROBES: [f64; 3] = [0.739_085_133_2, 1.324_717_957_2, -0.567_143_290_4];
    let end = slab.ps.get_expr(ExpressionI(usize::MAX)) as *const _;
    let mut inexact = false;
    for i in 0.. {
        if std::ptr::eq(slab.ps.get_expr(ExpressionI(i)), end) {
            break;
        }
        let ins = slab.ps.get_expr(ExpressionI(i)).compile(
            &slab.ps,
            &mut slab.cs,
            &mut fasteval2::EmptyNamespace,
        );
        for v in PROBES {
            let mut ns = |name: &str, args: Vec<f64>| -> Option<f64> {
                if args.is_empty() && variable(name, &Point::default()).is_some() {
                    return Some(v);
                }
                call(name, &args)
            };
            let tree = slab.ps.get_expr(ExpressionI(i)).eval(slab, &mut ns);
            let comp = ins.eval(slab, &mut ns);
            let (Ok(tree), Ok(comp)) = (tree, comp) else {
                continue;
            };
            if tree.to_bits() != comp.to_bits() && !(tree.is_nan() && comp.is_nan()) {
                if !tree.is_finite() && comp.is_finite() {
                    return Some(Folding::DropsNonFinite(tree));
                }
                inexact = true;
            }
        }
    }
    inexact.then_some(Folding::Inexact)
}

/// The value of the first sub-expression of the parse slab (the whole expression, each
/// parenthesized part, each function argument) that uses no variable and is not finite.
fn non_finite_constant(slab: &Slab) -> Option<f64> {
    // `get_expr` answers an index past the end with the slab's default expression.
    let end = slab.ps.get_expr(ExpressionI(usize::MAX));
    (0..)
        .map(|i| slab.ps.get_expr(ExpressionI(i)))
        .take_while(|e| !std::ptr::eq(*e, end))
        .find_map(|e| {
            let mut uses_variable = false;
            let mut ns = |name: &str, args: Vec<f64>| -> Option<f64> {
                if args.is_empty() && variable(name, &Point::default()).is_some() {
                    uses_variable = true;
                    return Some(0.0);
                }
                call(name, &args)
            };
            let v = e.eval(slab, &mut ns).ok()?;
            (!uses_variable && !v.is_finite()).then_some(v)
        })
}

/// A scene value that is either a number or an expression.
#[derive(Debug)]
pub enum Scalar {
    Const(f64),
    Expr(Box<Expr>),
}

impl Scalar {
    pub fn eval(&self, p: &Point) -> f64 {
        match self {
            Scalar::Const(v) => *v,
            Scalar::Expr(e) => e.eval(p),
        }
    }

    /// True if the value is the constant 0 (an effect that vanishes identically).
    pub fn is_zero(&self) -> bool {
        matches!(self, Scalar::Const(v) if *v == 0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_power_binds_tighter_than_a_unary_minus() {
        let at = |e: &str, s: f64| {
            Expr::parse(e, &["s", "x"], "k").unwrap().eval(&Point {
                s,
                x: s,
                ..Point::default()
            })
        };
        let cases: [(&str, f64, f64); 12] = [
            ("-s^2", 3.0, -9.0),
            ("-2^2", 0.0, -4.0),
            ("2*-3^2", 0.0, -18.0),
            ("2^-1", 0.0, 0.5),
            ("2^-s^2", 1.0, 0.5f64.powi(1)),
            ("exp(-(s/0.5)^0.3)", 0.5, (-1.0f64).exp()),
            ("exp(-(s/2)^0.5)", 8.0, (-2.0f64).exp()),
            ("-0.1*x*(2-x)", 1.0, -0.1),
            ("1e-3^2 - s", 0.0, 1e-6),
            ("- s ^ 2 + 1", 2.0, -3.0),
            ("-pow(s, 2)^2", 2.0, -16.0),
            ("3 - -s^2", 2.0, 7.0),
        ];
        for (e, s, want) in cases {
            let got = at(e, s);
            assert!(
                (got - want).abs() <= 1e-15 * want.abs().max(1.0),
                "{e} at {s}: {got}"
            );
        }
        assert_eq!(power_before_negation("-(0.0625)^0.3"), "-((0.0625)^0.3)");
        assert_eq!(power_before_negation("a - b^2"), "a - b^2");
        assert_eq!(power_before_negation("2*μ^2 + é"), "2*μ^2 + é");
    }

    #[test]
    fn paper_loads_evaluate() {
        let f = Expr::parse("-0.1*x*(2-x)*min(t, 0.2)", &["x", "y", "t"], "k").unwrap();
        let p = Point {
            x: 0.5,
            t: 0.1,
            ..Default::default()
        };
        assert!((f.eval(&p) - (-0.1 * 0.5 * 1.5 * 0.1)).abs() < 1e-17);
        let g = Expr::parse(
            "if(t <= 0.5, 0.01*(1-y)*t, 0.01*(1-y)*0.2)",
            &["y", "t"],
            "k",
        )
        .unwrap();
        let p = Point {
            y: 0.25,
            t: 0.75,
            ..Default::default()
        };
        assert!((g.eval(&p) - 0.01 * 0.75 * 0.2).abs() < 1e-18);
        let h = Expr::parse("1/2 + exp(-10*s)", &["s"], "k").unwrap();
        let p = Point {
            s: 0.1,
            ..Default::default()
        };
        assert_eq!(h.eval(&p), 0.5 + (-1.0f64).exp());
    }

    /// fasteval2's compiler folds a NaN constant into 1 (or drops it from a sum): the reason
    /// `Expr` evaluates the parse tree. When this fails, the library has changed: check
    /// whether compiling is safe again.
    #[test]
    fn compiler_folds_nan_away() {
        use fasteval2::Compiler;
        let mut slab = Slab::new();
        let parsed = Parser::new().parse("0/0", &mut slab.ps).unwrap();
        let compiled =
            parsed
                .from(&slab.ps)
                .compile(&slab.ps, &mut slab.cs, &mut fasteval2::EmptyNamespace);
        let v = compiled
            .eval(&slab, &mut fasteval2::EmptyNamespace)
            .unwrap();
        assert_eq!(v, 1.0, "fasteval2's folding of 0/0 changed");
    }

    #[test]
    fn non_finite_constants_are_refused() {
        for src in [
            "0/0",
            "0*(1/0)",
            "(0-0)/(1-1)",
            "-(0/0)",
            "1/0",
            "x + 0/0",
            "x*0/0",
            "if(t > 1, 0/0, 1)",
            "ln(0)",
            "x + (sqrt(-1))",
        ] {
            let e = Expr::parse(src, &["x", "t"], "load.traction[0].value[1]").unwrap_err();
            let msg = e.to_string();
            assert!(msg.contains("load.traction[0].value[1]"), "{src}: {msg}");
            assert!(msg.contains("without variables"), "{src}: {msg}");
        }
        // Parts that use a variable are judged where they are evaluated (loads at every
        // quadrature point: at t = 0 before the run, later during it).
        // A tiny constant that the compiler would drop is kept.
        let e = Expr::parse("1e-20 + 0*x", &["x"], "k").unwrap();
        assert_eq!(e.eval(&Point::default()), 1e-20);
        let e = Expr::parse("1/x", &["x"], "k").unwrap();
        assert!(e.eval(&Point::default()).is_infinite());
        assert_eq!(
            e.eval(&Point {
                x: 4.0,
                ..Default::default()
            }),
            0.25
        );
    }

    #[test]
    fn unknown_names_and_syntax_errors_are_refused() {
        let e = Expr::parse("x + q", &["x"], "load.body[0].value[0]").unwrap_err();
        assert!(e.to_string().contains("variable 'q'"), "{e}");
        assert!(e.to_string().contains("load.body[0].value[0]"), "{e}");
        let e = Expr::parse("s*t", &["s"], "r").unwrap_err();
        assert!(e.to_string().contains("variable 't'"), "{e}");
        let e = Expr::parse("foo(x)", &["x"], "r").unwrap_err();
        assert!(e.to_string().contains("function 'foo'"), "{e}");
        let e = Expr::parse("print(\"hi\", x)", &["x"], "r").unwrap_err();
        assert!(e.to_string().contains("print()"), "{e}");
        assert!(Expr::parse("printer", &["x"], "r").is_err()); // unknown variable, not print
        let e = Expr::parse("(x + ", &["x"], "r").unwrap_err();
        assert!(e.to_string().contains("cannot parse"), "{e}");
    }
}
