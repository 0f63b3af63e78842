//! Scene expressions: loads f0(x, y, z, t), f2(x, y, z, t), F(x, y, z), μ(x, y, z) and a
//! relaxation kernel r(s). Parsed once, when the scene is read, by the recursive-descent
//! parser below into a flat postfix program that `eval` runs on a small stack. The user
//! documentation is docs/expressions.md; this is the contract it describes.
//!
//! Grammar (lowest precedence first; every binary operator but `^` is left-associative):
//!
//! ```text
//! expr    := and ( "||" and )*
//! and     := cmp ( "&&" cmp )*
//! cmp     := sum ( ("<" | "<=" | ">" | ">=" | "==" | "!=") sum )?   -- no chains: a<b<c
//! sum     := product ( ("+" | "-") product )*
//! product := unary ( ("*" | "/" | "%") unary )*
//! unary   := ("-" | "+" | "!") unary | power
//! power   := primary ( "^" unary )?                                 -- right-associative
//! primary := number | name | name "(" expr ( "," expr )* ")" | "(" expr ")"
//! number  := digits [ "." digits ] [ ("e" | "E") [sign] digits ]    -- also ".5", "5."
//! ```
//!
//! So `-s^2` = −(s²), `2^-s^2` = 2^(−(s²)), `2^3^2` = 2^9, `2*5%3` = (2·5) fmod 3 = 1. A
//! number directly followed by a letter (`2k`, `1u`, `2x`) is refused: there are no unit
//! suffixes and no implicit multiplication. Values are f64 and every operation is the IEEE
//! one of std: `+ - * /`; `%` is C's fmod (the sign of the dividend); `^` and `pow` are
//! `powf`; the functions call std (the platform libm): abs sqrt exp ln log10 log2 sin cos
//! tan asin acos atan sinh cosh tanh floor ceil round (half away from zero) trunc sign,
//! atan2(y, x), min and max of two or more arguments (applied left to right), if(c, a, b).
//! `log` is refused with a pointer to `ln` and `log10`: it meant log10 before, and silently
//! changing the value of existing scenes is worse than asking. Constants: `pi`, `e`.
//!
//! Truth values: comparisons are exact and give 1 or 0; `&&`, `||`, `!` treat 0 as false and
//! anything else as true and give 1 or 0; `if(c, a, b)` is a where c ≠ 0, else b (both
//! branches are computed; the value of the other one does not matter). NaN propagates: a
//! comparison, `&&`, `||`, `!`, `if`, `min`, `max` or `sign` with a NaN operand (a NaN
//! condition, for `if`) gives NaN, so an undefined part never picks a branch; the value
//! becomes non-finite and the caller's finiteness check (loads: every quadrature point each
//! step; kernels: every lag) reports it naming the key.
//!
//! Compilation folds every operation whose operands are all constants by calling the very
//! function that evaluation calls, so folding is exact: the folded program gives the bits the
//! unfolded one would. A constant part (one that uses no variable) that is not finite (`1/0`,
//! `ln(0)`, `if(ln(-1) > 0, 1, 2)`) is refused when the scene is read, as is a number that
//! overflows. Variables outside the key's list (`z` in a 2D scene, `t` in a kernel) and
//! unknown names are refused naming the key. Parsing reads each character a bounded number of
//! times (linear time); nesting (parentheses, calls, unary operators, exponents) deeper than
//! [`MAX_DEPTH`] is refused, so the recursion cannot overflow the stack.

use crate::{Error, Result};

/// The deepest nesting of parentheses, function calls, unary operators and exponents.
pub const MAX_DEPTH: usize = 100;

/// The names of the variables, in the order of `Point`'s fields.
const VARIABLES: [&str; 5] = ["x", "y", "z", "t", "s"];

/// Values of the variables an expression may use.
#[derive(Clone, Copy, Debug, Default)]
pub struct Point {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub t: f64,
    pub s: f64,
}

/// A function of one value, and of two.
type F1 = fn(f64) -> f64;
type F2 = fn(f64, f64) -> f64;

/// One instruction of the postfix program.
#[derive(Clone, Copy, Debug)]
enum Op {
    Const(f64),
    Var(u8),
    Unary(F1),
    Binary(F2),
    If,
}

impl Op {
    /// How many values the instruction takes from the stack.
    fn arity(self) -> usize {
        match self {
            Op::Const(_) | Op::Var(_) => 0,
            Op::Unary(_) => 1,
            Op::Binary(_) => 2,
            Op::If => 3,
        }
    }
}

/// 1 or 0, or NaN where an operand is NaN.
fn truth(a: f64, b: f64, value: bool) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else if value {
        1.0
    } else {
        0.0
    }
}

fn neg(a: f64) -> f64 {
    -a
}
fn not(a: f64) -> f64 {
    truth(a, a, a == 0.0)
}
fn add(a: f64, b: f64) -> f64 {
    a + b
}
fn sub(a: f64, b: f64) -> f64 {
    a - b
}
fn mul(a: f64, b: f64) -> f64 {
    a * b
}
fn div(a: f64, b: f64) -> f64 {
    a / b
}
fn rem(a: f64, b: f64) -> f64 {
    a % b
}
fn pow(a: f64, b: f64) -> f64 {
    a.powf(b)
}
fn lt(a: f64, b: f64) -> f64 {
    truth(a, b, a < b)
}
fn le(a: f64, b: f64) -> f64 {
    truth(a, b, a <= b)
}
fn gt(a: f64, b: f64) -> f64 {
    truth(a, b, a > b)
}
fn ge(a: f64, b: f64) -> f64 {
    truth(a, b, a >= b)
}
fn eq(a: f64, b: f64) -> f64 {
    truth(a, b, a == b)
}
fn ne(a: f64, b: f64) -> f64 {
    truth(a, b, a != b)
}
fn and(a: f64, b: f64) -> f64 {
    truth(a, b, a != 0.0 && b != 0.0)
}
fn or(a: f64, b: f64) -> f64 {
    truth(a, b, a != 0.0 || b != 0.0)
}
/// The smaller, the first of equal ones (so min(-0, 0) = -0), NaN if either is NaN.
fn min(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else if b < a {
        b
    } else {
        a
    }
}
fn max(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else if b > a {
        b
    } else {
        a
    }
}
fn sign(a: f64) -> f64 {
    if a > 0.0 {
        1.0
    } else if a < 0.0 {
        -1.0
    } else if a == 0.0 {
        0.0
    } else {
        f64::NAN
    }
}
fn if_(c: f64, a: f64, b: f64) -> f64 {
    if c.is_nan() {
        f64::NAN
    } else if c != 0.0 {
        a
    } else {
        b
    }
}

/// The functions of one argument.
const UNARY: [(&str, F1); 20] = [
    ("abs", f64::abs),
    ("sqrt", f64::sqrt),
    ("exp", f64::exp),
    ("ln", f64::ln),
    ("log10", f64::log10),
    ("log2", f64::log2),
    ("sin", f64::sin),
    ("cos", f64::cos),
    ("tan", f64::tan),
    ("asin", f64::asin),
    ("acos", f64::acos),
    ("atan", f64::atan),
    ("sinh", f64::sinh),
    ("cosh", f64::cosh),
    ("tanh", f64::tanh),
    ("floor", f64::floor),
    ("ceil", f64::ceil),
    ("round", f64::round),
    ("trunc", f64::trunc),
    ("sign", sign),
];

/// The functions of two arguments; min and max take two or more.
const BINARY: [(&str, F2); 4] = [
    ("pow", pow),
    ("atan2", f64::atan2),
    ("min", min),
    ("max", max),
];

/// The list of functions for error messages.
const FUNCTIONS: &str = "abs, sqrt, exp, ln, log10, log2, sin, cos, tan, asin, acos, atan, \
     sinh, cosh, tanh, floor, ceil, round, trunc, sign, pow, atan2, min, max, if(c, a, b); \
     constants pi, e";

/// A lexical token.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Tok<'a> {
    Num(f64),
    Name(&'a str),
    Sym(&'static str),
    End,
}

/// The symbols, longest first so that `<=` is not read as `<`.
const SYMBOLS: [&str; 18] = [
    "<=", ">=", "==", "!=", "&&", "||", "+", "-", "*", "/", "%", "^", "(", ")", ",", "<", ">", "!",
];

struct Parser<'a> {
    src: &'a str,
    pos: usize,
    allowed: &'a [&'a str],
    code: Vec<Op>,
    depth: usize,
    /// The token after `pos` and the position after it, once looked at.
    ahead: Option<(Tok<'a>, usize)>,
    /// The stack height after the code so far, and its maximum.
    height: usize,
    max_height: usize,
}

/// A parse error: what is wrong and the byte offset where it was found.
type Fail = (String, usize);

impl<'a> Parser<'a> {
    /// The token at the current position and the position after it.
    fn lex(&self) -> std::result::Result<(Tok<'a>, usize), Fail> {
        let b = self.src.as_bytes();
        let mut i = self.pos;
        while i < b.len() && b[i].is_ascii_whitespace() {
            i += 1;
        }
        let Some(&c) = b.get(i) else {
            return Ok((Tok::End, i));
        };
        if c.is_ascii_digit() || (c == b'.' && b.get(i + 1).is_some_and(u8::is_ascii_digit)) {
            return self.number(i);
        }
        if c.is_ascii_alphabetic() || c == b'_' {
            let end = (i..b.len())
                .find(|&j| !(b[j].is_ascii_alphanumeric() || b[j] == b'_'))
                .unwrap_or(b.len());
            return Ok((Tok::Name(&self.src[i..end]), end));
        }
        let rest = &self.src[i..];
        for (bad, hint) in [
            ("**", "'**' is not an operator: write a power as a^b"),
            ("=", "'=' alone is not an operator: compare with =="),
            ("&", "'&' alone is not an operator: write && for 'and'"),
            (
                "|",
                "'|' alone is not an operator: write || for 'or', abs(a) for |a|",
            ),
        ] {
            let taken = SYMBOLS.iter().any(|s| s.len() > 1 && rest.starts_with(s));
            if rest.starts_with(bad) && !taken {
                return Err((hint.into(), i));
            }
        }
        if let Some(s) = SYMBOLS.iter().find(|s| rest.starts_with(*s)) {
            return Ok((Tok::Sym(s), i + s.len()));
        }
        let ch = rest.chars().next().unwrap_or('?');
        Err((
            format!("{ch:?} is not allowed (names are ASCII letters, digits and '_')"),
            i,
        ))
    }

    /// A number literal starting at `i`; a letter right after it is refused.
    fn number(&self, i: usize) -> std::result::Result<(Tok<'a>, usize), Fail> {
        let b = self.src.as_bytes();
        let digits = |mut j: usize| {
            while j < b.len() && b[j].is_ascii_digit() {
                j += 1;
            }
            j
        };
        let mut end = digits(i);
        if b.get(end) == Some(&b'.') {
            end = digits(end + 1);
        }
        if matches!(b.get(end), Some(b'e' | b'E')) {
            let sign = usize::from(matches!(b.get(end + 1), Some(b'+' | b'-')));
            if b.get(end + 1 + sign).is_some_and(u8::is_ascii_digit) {
                end = digits(end + 1 + sign);
            }
        }
        let text = &self.src[i..end];
        if let Some(&c) = b.get(end) {
            if c.is_ascii_alphanumeric() || c == b'_' || c == b'.' {
                let next = &self.src[end..end + 1];
                return Err((
                    format!(
                        "the number {text} is followed by {next:?}: there are no unit suffixes \
                         and no implicit multiplication (write 2e3, not 2k; 2*x, not 2x)"
                    ),
                    i,
                ));
            }
        }
        let v: f64 = text
            .parse()
            .map_err(|_| (format!("{text:?} is not a number"), i))?;
        if !v.is_finite() {
            return Err((format!("the number {text} overflows a double"), i));
        }
        Ok((Tok::Num(v), end))
    }

    /// The next token, lexed once however often it is looked at.
    fn peek(&mut self) -> std::result::Result<Tok<'a>, Fail> {
        if self.ahead.is_none() {
            self.ahead = Some(self.lex()?);
        }
        Ok(self.ahead.expect("just set").0)
    }

    fn advance(&mut self) -> std::result::Result<Tok<'a>, Fail> {
        self.peek()?;
        let (tok, end) = self.ahead.take().expect("peeked");
        self.pos = end;
        Ok(tok)
    }

    /// Takes the symbol `s` if it comes next.
    fn eat(&mut self, s: &str) -> std::result::Result<bool, Fail> {
        let taken = matches!(self.peek()?, Tok::Sym(t) if t == s);
        if taken {
            self.advance()?;
        }
        Ok(taken)
    }

    fn enter(&mut self) -> std::result::Result<(), Fail> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return Err((
                format!(
                    "it nests deeper than {MAX_DEPTH} levels (parentheses, calls, signs, powers)"
                ),
                self.pos,
            ));
        }
        Ok(())
    }

    /// Appends `op`, folding it into a constant where all its operands are constants.
    fn emit(&mut self, op: Op) -> std::result::Result<(), Fail> {
        let n = op.arity();
        let start = self.code.len() - n;
        let mut args = [0.0; 3];
        let constant = n > 0
            && self.code[start..]
                .iter()
                .zip(&mut args)
                .all(|(o, a)| match o {
                    Op::Const(c) => {
                        *a = *c;
                        true
                    }
                    _ => false,
                });
        self.height = self.height + 1 - n;
        self.max_height = self.max_height.max(self.height);
        if constant {
            let v = apply(op, &args[..n]);
            if !v.is_finite() {
                return Err((
                    format!(
                        "a part without variables evaluates to {v} (a division by zero, a \
                         function outside its domain or an overflow); write a finite value"
                    ),
                    self.pos,
                ));
            }
            self.code.truncate(start);
            self.code.push(Op::Const(v));
        } else {
            self.code.push(op);
        }
        Ok(())
    }
}

/// `op` applied to `args`: the very computation of `Expr::eval`, for constant folding.
fn apply(op: Op, args: &[f64]) -> f64 {
    match (op, args) {
        (Op::Unary(f), [a]) => f(*a),
        (Op::Binary(f), [a, b]) => f(*a, *b),
        (Op::If, [c, a, b]) => if_(*c, *a, *b),
        _ => unreachable!("arity checked by the caller"),
    }
}

/// The grammar of the module doc, one function per rule.
impl Parser<'_> {
    fn expr(&mut self) -> std::result::Result<(), Fail> {
        self.and()?;
        while self.eat("||")? {
            self.and()?;
            self.emit(Op::Binary(or))?;
        }
        Ok(())
    }

    fn and(&mut self) -> std::result::Result<(), Fail> {
        self.cmp()?;
        while self.eat("&&")? {
            self.cmp()?;
            self.emit(Op::Binary(and))?;
        }
        Ok(())
    }

    fn comparison(&mut self) -> std::result::Result<Option<F2>, Fail> {
        let ops: [(&str, F2); 6] = [
            ("<", lt),
            ("<=", le),
            (">", gt),
            (">=", ge),
            ("==", eq),
            ("!=", ne),
        ];
        Ok(match self.peek()? {
            Tok::Sym(s) => ops.iter().find(|(o, _)| *o == s).map(|(_, f)| *f),
            _ => None,
        })
    }

    fn cmp(&mut self) -> std::result::Result<(), Fail> {
        self.sum()?;
        if let Some(f) = self.comparison()? {
            self.advance()?;
            self.sum()?;
            self.emit(Op::Binary(f))?;
            if self.comparison()?.is_some() {
                return Err((
                    "comparisons do not chain: write a < b && b < c, not a < b < c".into(),
                    self.pos,
                ));
            }
        }
        Ok(())
    }

    fn sum(&mut self) -> std::result::Result<(), Fail> {
        self.product()?;
        loop {
            let f: F2 = match self.peek()? {
                Tok::Sym("+") => add,
                Tok::Sym("-") => sub,
                _ => return Ok(()),
            };
            self.advance()?;
            self.product()?;
            self.emit(Op::Binary(f))?;
        }
    }

    fn product(&mut self) -> std::result::Result<(), Fail> {
        self.unary()?;
        loop {
            let f: F2 = match self.peek()? {
                Tok::Sym("*") => mul,
                Tok::Sym("/") => div,
                Tok::Sym("%") => rem,
                _ => return Ok(()),
            };
            self.advance()?;
            self.unary()?;
            self.emit(Op::Binary(f))?;
        }
    }

    fn unary(&mut self) -> std::result::Result<(), Fail> {
        let f: Option<F1> = match self.peek()? {
            Tok::Sym("-") => Some(neg),
            Tok::Sym("!") => Some(not),
            Tok::Sym("+") => None,
            _ => return self.power(),
        };
        self.advance()?;
        self.enter()?;
        self.unary()?;
        self.depth -= 1;
        match f {
            Some(f) => self.emit(Op::Unary(f)),
            None => Ok(()),
        }
    }

    fn power(&mut self) -> std::result::Result<(), Fail> {
        self.primary()?;
        if self.eat("^")? {
            self.enter()?;
            self.unary()?;
            self.depth -= 1;
            self.emit(Op::Binary(pow))?;
        }
        Ok(())
    }

    fn primary(&mut self) -> std::result::Result<(), Fail> {
        let at = self.pos;
        match self.advance()? {
            Tok::Num(v) => self.emit(Op::Const(v)),
            Tok::Sym("(") => {
                self.enter()?;
                self.expr()?;
                self.depth -= 1;
                self.close(at)
            }
            Tok::Name(name) if self.eat("(")? => self.call(name, at),
            Tok::Name(name) => self.name(name, at),
            Tok::End => Err(("it ends where an operand is expected".into(), self.pos)),
            Tok::Sym(s) => Err((
                format!("{s:?} where an operand (a number, a name or '(') is expected"),
                self.pos - s.len(),
            )),
        }
    }

    /// Takes the ')' closing the '(' at `open`.
    fn close(&mut self, open: usize) -> std::result::Result<(), Fail> {
        match self.advance()? {
            Tok::Sym(")") => Ok(()),
            Tok::End => Err(("a ')' is missing".into(), open)),
            _ => Err((
                "expected ')' or an operator".into(),
                self.pos.saturating_sub(1),
            )),
        }
    }

    /// A variable or a constant.
    fn name(&mut self, name: &str, at: usize) -> std::result::Result<(), Fail> {
        let constant = match name {
            "pi" => Some(std::f64::consts::PI),
            "e" => Some(std::f64::consts::E),
            _ => None,
        };
        if let Some(c) = constant {
            return self.emit(Op::Const(c));
        }
        let allowed = self.allowed.join(", ");
        match VARIABLES.iter().position(|v| *v == name) {
            Some(i) if self.allowed.contains(&name) => self.emit(Op::Var(i as u8)),
            Some(_) => {
                let two_d = name == "z" && self.allowed.contains(&"x");
                let why = if two_d { " (a 2D model has no z)" } else { "" };
                Err((
                    format!("variable '{name}' is not available here{why}; allowed variables: {allowed}"),
                    at,
                ))
            }
            None => Err((
                format!(
                    "unknown variable '{name}'; allowed variables: {allowed}; constants: pi, e"
                ),
                at,
            )),
        }
    }

    /// The arguments of a call of `name` (its '(' taken) and the call.
    fn call(&mut self, name: &str, at: usize) -> std::result::Result<(), Fail> {
        let variadic = matches!(name, "min" | "max");
        self.enter()?;
        let mut n = 0;
        if !matches!(self.peek()?, Tok::Sym(")")) {
            loop {
                self.expr()?;
                n += 1;
                if n >= 2 && variadic {
                    let (_, f) = BINARY.iter().find(|(f, _)| *f == name).expect("min, max");
                    self.emit(Op::Binary(*f))?;
                }
                if !self.eat(",")? {
                    break;
                }
            }
        }
        self.depth -= 1;
        self.close(at + name.len())?;
        let wrong = |want: &str| Err((format!("{name}() takes {want}, not {n}"), at));
        if variadic {
            return if n >= 2 {
                Ok(())
            } else {
                wrong("two or more arguments")
            };
        }
        if let Some((_, f)) = UNARY.iter().find(|(f, _)| *f == name) {
            return if n == 1 {
                self.emit(Op::Unary(*f))
            } else {
                wrong("one argument")
            };
        }
        if let Some((_, f)) = BINARY.iter().find(|(f, _)| *f == name) {
            return if n == 2 {
                self.emit(Op::Binary(*f))
            } else {
                wrong("two arguments")
            };
        }
        if name == "if" {
            return if n == 3 {
                self.emit(Op::If)
            } else {
                wrong("three arguments (c, a, b)")
            };
        }
        Err((unknown_function(name), at))
    }
}

fn unknown_function(name: &str) -> String {
    match name {
        "log" => "log() is not defined (it meant log10 before): write ln(x) for the natural \
                  logarithm or log10(x) for the common one"
            .into(),
        "pi" | "e" => format!("{name} is a constant, not a function: write {name}"),
        _ => format!("unknown function '{name}'; the functions are {FUNCTIONS}"),
    }
}

/// `source` for an error message, shortened to its first 60 characters.
fn shown(source: &str) -> String {
    match source.char_indices().nth(60) {
        Some((i, _)) => format!("{:?}… ({} bytes)", &source[..i], source.len()),
        None => format!("{source:?}"),
    }
}

/// A parsed expression of some of the variables x, y, z, t, s.
pub struct Expr {
    source: String,
    code: Vec<Op>,
    /// The deepest stack `code` needs.
    height: usize,
}

impl std::fmt::Debug for Expr {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Expr({:?})", self.source)
    }
}

impl Expr {
    /// Parses `source`, allowing only the variables in `allowed`. `key` names the scene entry
    /// in error messages (e.g. `load.traction[0].value[1]`).
    pub fn parse(source: &str, allowed: &[&str], key: &str) -> Result<Expr> {
        let mut p = Parser {
            src: source,
            pos: 0,
            allowed,
            code: Vec::new(),
            depth: 0,
            ahead: None,
            height: 0,
            max_height: 0,
        };
        let parsed = p.expr().and_then(|()| match p.peek()? {
            Tok::End => Ok(()),
            _ => Err((
                "unexpected text; an operator or the end was expected".into(),
                p.pos,
            )),
        });
        if let Err((why, at)) = parsed {
            let column = source[..at.min(source.len())].chars().count() + 1;
            return Err(Error::input(format!(
                "{key}: cannot parse expression {}: {why} (at character {column})",
                shown(source)
            )));
        }
        Ok(Expr {
            source: source.to_string(),
            code: p.code,
            height: p.max_height,
        })
    }

    /// The value at `p`.
    pub fn eval(&self, p: &Point) -> f64 {
        let vars = [p.x, p.y, p.z, p.t, p.s];
        const SMALL: usize = 16;
        if self.height <= SMALL {
            run(&self.code, &vars, &mut [0.0; SMALL])
        } else {
            run(&self.code, &vars, &mut vec![0.0; self.height])
        }
    }

    pub fn source(&self) -> &str {
        &self.source
    }
}

/// Runs the postfix program on `stack`, which is deep enough.
fn run(code: &[Op], vars: &[f64; 5], stack: &mut [f64]) -> f64 {
    let mut n = 0;
    for op in code {
        match *op {
            Op::Const(c) => {
                stack[n] = c;
                n += 1;
            }
            Op::Var(i) => {
                stack[n] = vars[i as usize];
                n += 1;
            }
            Op::Unary(f) => stack[n - 1] = f(stack[n - 1]),
            Op::Binary(f) => {
                n -= 1;
                stack[n - 1] = f(stack[n - 1], stack[n]);
            }
            Op::If => {
                n -= 2;
                stack[n - 1] = if_(stack[n - 1], stack[n], stack[n + 1]);
            }
        }
    }
    stack[0]
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

    const ALL: &[&str] = &["x", "y", "z", "t", "s"];

    /// The value of `src` with every variable = `v`.
    fn at(src: &str, v: f64) -> f64 {
        let p = Point {
            x: v,
            y: v,
            z: v,
            t: v,
            s: v,
        };
        Expr::parse(src, ALL, "k").unwrap().eval(&p)
    }

    /// The message refusing `src` (with the key `k`), which must name the key.
    fn refused(src: &str, allowed: &[&str]) -> String {
        let e = Expr::parse(src, allowed, "load.body[0].value[1]").unwrap_err();
        let msg = e.to_string();
        assert!(matches!(e, Error::Input(_)), "{src}: {msg}");
        assert!(msg.contains("load.body[0].value[1]"), "{src}: {msg}");
        msg
    }

    #[test]
    fn unit_suffixes_and_implicit_products_are_refused() {
        for src in [
            "2k", "2m*t", "1u", "-2k^2", "2x", "1e", "2e3e", "3.5.1", "2_0",
        ] {
            let msg = refused(src, ALL);
            assert!(msg.contains("no unit suffixes"), "{src}: {msg}");
        }
        for (src, want) in [("2e3", 2e3), ("1.5E-3", 1.5e-3), (".5", 0.5), ("5.", 5.0)] {
            assert_eq!(at(src, 0.0), want, "{src}");
        }
        assert!(refused("1e400", ALL).contains("overflows"));
    }

    #[test]
    fn log_is_refused_with_a_pointer_to_ln_and_log10() {
        let msg = refused("log(x)", ALL);
        assert!(msg.contains("ln(x)") && msg.contains("log10(x)"), "{msg}");
        assert_eq!(at("ln(e)", 0.0), std::f64::consts::E.ln());
        assert_eq!(at("ln(x)", 2.0), 2f64.ln());
        assert_eq!(at("log10(x)", 1000.0), 1000f64.log10());
        assert_eq!(at("log2(x)", 8.0), 3.0);
    }

    #[test]
    fn remainder_is_fmod_at_the_precedence_of_products() {
        for (src, want) in [
            ("2*5%3", 1.0),
            ("2*(5%3)", 4.0),
            ("7%3*2", 2.0),
            ("1+7%3", 2.0),
            ("-7%3", -1.0),
            ("7%-3", 1.0),
            ("5.5%2", 1.5),
        ] {
            assert_eq!(at(src, 0.0), want, "{src}");
        }
    }

    #[test]
    fn comparisons_are_exact_and_give_one_or_zero() {
        for (src, want) in [
            ("if(1e-15 != 0, 1, 2)", 1.0),
            ("1e-300 == 0", 0.0),
            ("0.1 + 0.2 == 0.3", 0.0),
            ("x + 1e-17 == x", 1.0),
            ("x <= 1", 1.0),
            ("x < 1", 0.0),
            ("-0 == 0", 1.0),
        ] {
            assert_eq!(at(src, 1.0), want, "{src}");
        }
    }

    #[test]
    fn nan_propagates_through_min_max_comparisons_and_logic() {
        for src in [
            "max(-5e-3*t, ln(-t))",
            "min(ln(-t), 1)",
            "max(1, 2, ln(-t))",
            "if(ln(-t) > 0, 1, 2)",
            "ln(-t) == ln(-t)",
            "ln(-t) != 1",
            "ln(-t) && 0",
            "1 || ln(-t)",
            "!ln(-t)",
            "if(ln(-t), 1, 2)",
            "sign(ln(-t))",
        ] {
            assert!(at(src, 1.0).is_nan(), "{src}: {}", at(src, 1.0));
        }
        // The branch not taken may be undefined.
        assert_eq!(at("if(t > 0, 1/t, ln(-t))", 2.0), 0.5);
        // A constant part that is not finite is refused when the scene is read.
        for src in [
            "if(ln(-1) > 0, 1, 2)",
            "max(x, ln(-1))",
            "x + 0/0",
            "ln(0)",
            "1e308*10",
        ] {
            let msg = refused(src, ALL);
            assert!(msg.contains("without variables"), "{src}: {msg}");
        }
    }

    #[test]
    fn logic_gives_one_or_zero_and_comparisons_do_not_chain() {
        for (src, want) in [
            ("2 && 3", 1.0),
            ("2 && 0", 0.0),
            ("0 || 0.5", 1.0),
            ("0 || 0", 0.0),
            ("!2", 0.0),
            ("!0", 1.0),
            ("!!7", 1.0),
            ("(3 > 2) > 1", 0.0),
            ("3 > 2 && 2 > 1", 1.0),
            ("1 || 0 && 0", 1.0),
            ("(x < 2) == 0", 1.0),
        ] {
            assert_eq!(at(src, 5.0), want, "{src}");
        }
        for src in ["3>2>1", "x < y <= 3", "1 == 1 == 1", "x < 2 == 1"] {
            let msg = refused(src, ALL);
            assert!(
                msg.contains("do not chain") && msg.contains("&&"),
                "{src}: {msg}"
            );
        }
        assert!(refused("x = 1", ALL).contains("=="));
        assert!(refused("x & 1", ALL).contains("&&"));
    }

    #[test]
    fn a_power_is_right_associative_and_binds_tighter_than_a_sign() {
        let cases: [(&str, f64, f64); 13] = [
            ("-s^2", 3.0, -9.0),
            ("-2^2", 0.0, -4.0),
            ("2*-3^2", 0.0, -18.0),
            ("2^-1", 0.0, 0.5),
            ("2^-s^2", 1.0, 0.5),
            ("2^3^2", 0.0, 512.0),
            ("(2^3)^2", 0.0, 64.0),
            ("exp(-(s/2)^0.5)", 8.0, (-2.0f64).exp()),
            ("1e-3^2 - s", 0.0, 1e-3f64.powf(2.0)),
            ("- s ^ 2 + 1", 2.0, -3.0),
            ("-pow(s, 2)^2", 2.0, -16.0),
            ("3 - -s^2", 2.0, 7.0),
            ("!s^2", 0.0, 1.0),
        ];
        for (src, s, want) in cases {
            assert_eq!(at(src, s), want, "{src} at {s}");
        }
    }

    #[test]
    fn operations_run_left_to_right_as_written() {
        // The paper's loads: the IEEE operations in the written order, bit for bit.
        let (x, t) = (0.3, 0.15);
        let p = Point {
            x,
            t,
            ..Point::default()
        };
        let e = Expr::parse("-0.1*x*(2-x)*min(t, 0.2)", &["x", "y", "t"], "k").unwrap();
        assert_eq!(e.eval(&p).to_bits(), (-0.1 * x * (2.0 - x) * t).to_bits());
        let e = Expr::parse("0.5*exp(-5*x)/(1 + x) - x - t", ALL, "k").unwrap();
        let want = 0.5 * (-5.0 * x).exp() / (1.0 + x) - x - t;
        assert_eq!(e.eval(&p).to_bits(), want.to_bits());
        // Folding performs the same operations: a constant part gives the bits that the same
        // part of variables gives.
        let folded = at("exp(0.1)^1.7 - sin(2)/3 % 0.7", 0.0);
        let p = Point {
            x: 0.1,
            y: 1.7,
            z: 2.0,
            t: 3.0,
            s: 0.7,
        };
        let e = Expr::parse("exp(x)^y - sin(z)/t % s", ALL, "k").unwrap();
        assert_eq!(folded.to_bits(), e.eval(&p).to_bits());
    }

    #[test]
    fn unknown_names_and_variables_outside_the_key_are_refused() {
        assert!(refused("x + q", &["x"]).contains("unknown variable 'q'"));
        assert!(refused("s*t", &["s"]).contains("variable 't' is not available"));
        let msg = refused("x + z", &["x", "y", "t"]);
        assert!(msg.contains("a 2D model has no z"), "{msg}");
        assert!(refused("foo(x)", &["x"]).contains("unknown function 'foo'"));
        assert!(refused("pi()", &["x"]).contains("constant"));
        assert!(refused("min(x)", &["x"]).contains("two or more"));
        assert!(refused("if(x, 1)", &["x"]).contains("three arguments"));
        assert!(refused("x ** 2", &["x"]).contains("a^b"));
        assert!(refused("(x + ", &["x"]).contains("operand"));
        assert!(refused("(x + 1", &["x"]).contains("')' is missing"));
        assert!(refused("x + 1)", &["x"]).contains("unexpected"));
        assert!(refused("2*μ", &["x"]).contains("'μ' is not allowed"));
        assert!(refused("", &["x"]).contains("operand"));
    }

    #[test]
    fn parsing_is_linear_and_nesting_is_bounded() {
        let key = "load.body[0].value[1]";
        // A megabyte: parsed (or refused) in well under a second.
        for (src, ok) in [
            ("x*".repeat(500_000) + "x", true),
            ("1+".repeat(500_000) + "1", true),
            ("(".repeat(1_000_000), false),
            ("-".repeat(1_000_000) + "x", false),
            ("2^".repeat(500_000) + "x", false),
            ("min(x,".repeat(200_000), false),
        ] {
            let start = std::time::Instant::now();
            let got = Expr::parse(&src, &["x"], key);
            let took = start.elapsed().as_secs_f64();
            assert!(took < 1.0, "{} bytes took {took} s", src.len());
            assert_eq!(got.is_ok(), ok);
            if let Err(e) = got {
                let msg = e.to_string();
                assert!(
                    msg.contains(key) && msg.contains("deeper than 100"),
                    "{msg}"
                );
                assert!(msg.len() < 400, "the message quotes only the start: {msg}");
            }
        }
        let nested = |n: usize| "(".repeat(n) + "x" + &")".repeat(n);
        assert_eq!(at(&nested(MAX_DEPTH), 2.0), 2.0);
        assert!(refused(&nested(MAX_DEPTH + 1), &["x"]).contains("deeper"));
        // A deep stack (a right-nested sum) evaluates on the heap.
        let deep = "x+(".repeat(90) + "x" + &")".repeat(90);
        assert_eq!(at(&deep, 1.0), 91.0);
    }
}
