//! Scene expressions: loads f0(x, y, z, t), f2(x, y, z, t), F(x, y, z), μ(x, y, z) and a
//! relaxation kernel r(s), parsed once by `fasteval2` (MIT, maintained fork of fasteval;
//! every literal is an f64, so `1/2` is 0.5, not an integer division).
//!
//! The parse tree is evaluated as it stands, not fasteval's compiled form: the compiler's
//! constant folding compares folded constants with 1 and 0 up to 8ε, and NaN compares as
//! neither, so `0/0` compiled to the constant 1, `x + 0/0` to `x` and `-(0/0)` to −1
//! (fasteval2 2.1; `compiler_folds_nan_away` below pins that behaviour, so an upgrade that
//! fixes it shows). Every part of an expression that uses no variable (the whole, each
//! parenthesized part, each function argument) must be finite: `0/0`, `0*(1/0)` or
//! `(0-0)/(1-1)` are refused when the scene is read; `x + 0/0` is NaN wherever it is
//! evaluated, which the loads' check at t = 0 refuses before the run.
//!
//! Beyond fasteval's built-ins (`min`, `max`, `abs`, `sin`, …, `log(base, x)`, comparison and
//! `&&`/`||` operators) an expression may call `if(cond, a, b)`, `exp`, `ln`, `sqrt`, `pow`,
//! `tanh` and use the constants `pi` and `e`. Unknown variables and functions are refused when
//! the scene is read, not in the middle of a run.

use crate::{Error, Result};
use fasteval2::{Evaler, ExpressionI, Parser, Slab};

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
        let parsed = Parser::new().parse(source, &mut slab.ps).map_err(|e| {
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
        if let Some(v) = non_finite_constant(&slab) {
            return Err(Error::input(format!(
                "{key}: expression {source:?} has a part without variables that evaluates to \
                 {v} (a division by zero, or a function outside its domain); write a finite \
                 value"
            )));
        }
        Ok(Expr {
            source: source.to_string(),
            slab,
            root: parsed,
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
        self.root
            .from(&self.slab.ps)
            .eval(&self.slab, &mut ns)
            .unwrap_or(f64::NAN)
    }

    pub fn source(&self) -> &str {
        &self.source
    }
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
        for src in ["x + 0/0", "ln(0)*t"] {
            let e = Expr::parse(src, &["x", "t"], "k").unwrap();
            assert!(!e.eval(&Point::default()).is_finite(), "{src}");
        }
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
