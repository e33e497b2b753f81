//! User formulas f(x, y, t) for loads and initial data: parsed once into a tree, evaluated
//! many times by walking it.
//!
//! The grammar is the conventional one (a small Pratt parser): `-x^2 = -(x^2)`, `2^-1 = 0.5`,
//! `x^y^z = x^(y^z)`, as in every textbook and spreadsheet. Errors are one sentence naming the
//! 1-based character position and the expected input; unknown names are listed with the
//! allowed ones.
//!
//! Evaluation applies exactly one `f64` operation per tree node: `+ - * /` and unary minus as
//! written, `^` as `powf`, each function as the `f64` method of its name (`sign` is `signum`,
//! `log` is `ln`, `min`/`max`/`atan2` are `f64::min`/`max`/`atan2`). Subtrees without x, y and
//! t are computed once at parse time with the same operations, so folding never changes a
//! value.
//!
//! Grammar (whitespace is ignored):
//! ```text
//! expr    := term (('+' | '-') term)*
//! term    := factor (('*' | '/') factor)*
//! factor  := ('-' | '+') factor | power
//! power   := primary ('^' factor)?            right-associative, binds tighter than unary minus
//! primary := number | x | y | t | constant | function '(' expr (',' expr)* ')' | '(' expr ')'
//! number  := digits ['.' digits] [('e' | 'E') ['+' | '-'] digits]    (also '.5', '2.')
//! ```
//! Constants: `pi` (also `PI`, `π`), `e`. Functions of one argument: see [`FUNCTIONS`];
//! `log` is the natural logarithm (as `ln`). `min` and `max` take two or more arguments
//! (`min(a, b, c) = min(min(a, b), c)`), `atan2(y, x)` exactly two.

use std::fmt;

/// Longest accepted formula, in characters (a guard for a public service, not a modelling limit).
pub const MAX_LEN: usize = 1000;

/// Deepest accepted nesting of parentheses, signs and powers.
const MAX_DEPTH: usize = 64;

/// A function of one argument.
type Fn1 = fn(f64) -> f64;
/// A function of two arguments, or a binary operator.
type Fn2 = fn(f64, f64) -> f64;

/// Functions of one argument, as written in formulas.
const FUNCTIONS: &[(&str, Fn1)] = &[
    ("abs", f64::abs),
    ("sign", f64::signum),
    ("signum", f64::signum),
    ("sqrt", f64::sqrt),
    ("cbrt", f64::cbrt),
    ("exp", f64::exp),
    ("ln", f64::ln),
    ("log", f64::ln),
    ("log2", f64::log2),
    ("log10", f64::log10),
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
];

/// Functions of two (min, max: two or more) arguments.
const BINARY_FUNCTIONS: &[(&str, Fn2)] =
    &[("min", f64::min), ("max", f64::max), ("atan2", f64::atan2)];

/// Unary minus.
fn neg(a: f64) -> f64 {
    -a
}

/// The binary operator written `op`.
fn operator(op: char) -> Fn2 {
    match op {
        '+' => |a, b| a + b,
        '-' => |a, b| a - b,
        '*' => |a, b| a * b,
        '/' => |a, b| a / b,
        _ => f64::powf,
    }
}

/// Named constants.
const CONSTANTS: &[(&str, f64)] = &[
    ("pi", std::f64::consts::PI),
    ("PI", std::f64::consts::PI),
    ("π", std::f64::consts::PI),
    ("e", std::f64::consts::E),
];

/// The coordinates a formula may use, in the order of [`Expr::eval`]'s arguments.
/// Variables in the order of the evaluation point (x, y, t, z): z last so 2D callers that
/// never bind it keep their indices.
const VARIABLES: [&str; 4] = ["x", "y", "t", "z"];

/// A parsed formula f(x, y, t).
#[derive(Clone)]
pub struct Expr {
    source: String,
    tree: Ast,
    uses: [bool; 4],
}

impl fmt::Debug for Expr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_tuple("Expr").field(&self.source).finish()
    }
}

impl Expr {
    /// Parses a formula in x, y, t. Errors are one readable sentence (with a 1-based character
    /// position where that helps).
    pub fn parse(src: &str) -> Result<Expr, String> {
        let len = src.chars().count();
        if len > MAX_LEN {
            return Err(format!(
                "formula too long: {len} characters (at most {MAX_LEN})"
            ));
        }
        let tokens = tokenize(src)?;
        let mut parser = Parser {
            tokens: &tokens,
            pos: 0,
            depth: 0,
        };
        let tree = parser.expr(0)?;
        if let Some(tok) = parser.tokens.get(parser.pos) {
            return Err(match tok.kind {
                Tok::RParen => format!("unmatched ')' at position {}", tok.pos),
                _ => format!(
                    "expected an operator (+ - * / ^) at position {}, found {} (write 2*x, not 2x)",
                    tok.pos,
                    tok.kind.describe()
                ),
            });
        }
        let mut uses = [false; 4];
        tree.mark_variables(&mut uses);
        Ok(Expr {
            source: src.to_string(),
            tree,
            uses,
        })
    }

    /// f(x, y, t).
    #[inline]
    pub fn eval(&self, x: f64, y: f64, t: f64) -> f64 {
        self.tree.eval(&[x, y, t, 0.0])
    }

    /// Value at the point (x, y, z) and time t.
    #[inline]
    pub fn eval3(&self, x: f64, y: f64, z: f64, t: f64) -> f64 {
        self.tree.eval(&[x, y, t, z])
    }

    pub fn uses_z(&self) -> bool {
        self.uses[3]
    }

    pub fn uses_x(&self) -> bool {
        self.uses[0]
    }

    pub fn uses_y(&self) -> bool {
        self.uses[1]
    }

    pub fn uses_t(&self) -> bool {
        self.uses[2]
    }

    /// The formula as the user wrote it.
    pub fn source(&self) -> &str {
        &self.source
    }
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Num(f64),
    Ident(String),
    Op(char),
    LParen,
    RParen,
    Comma,
}

impl Tok {
    fn describe(&self) -> String {
        match self {
            Tok::Num(v) => format!("the number {v}"),
            Tok::Ident(s) => format!("'{s}'"),
            Tok::Op(c) => format!("'{c}'"),
            Tok::LParen => "'('".to_string(),
            Tok::RParen => "')'".to_string(),
            Tok::Comma => "','".to_string(),
        }
    }
}

struct Token {
    kind: Tok,
    /// 1-based character position in the source.
    pos: usize,
}

fn tokenize(src: &str) -> Result<Vec<Token>, String> {
    let chars: Vec<char> = src.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        let pos = i + 1;
        if c.is_whitespace() {
            i += 1;
            continue;
        }
        let kind = if c.is_ascii_digit() || c == '.' {
            let start = i;
            while i < chars.len() && chars[i].is_ascii_digit() {
                i += 1;
            }
            if i < chars.len() && chars[i] == '.' {
                i += 1;
                while i < chars.len() && chars[i].is_ascii_digit() {
                    i += 1;
                }
            }
            // An exponent only when digits follow: "2e" is 2 followed by the constant e.
            if i < chars.len() && (chars[i] == 'e' || chars[i] == 'E') {
                let mut j = i + 1;
                if j < chars.len() && (chars[j] == '+' || chars[j] == '-') {
                    j += 1;
                }
                if j < chars.len() && chars[j].is_ascii_digit() {
                    while j < chars.len() && chars[j].is_ascii_digit() {
                        j += 1;
                    }
                    i = j;
                }
            }
            let text: String = chars[start..i].iter().collect();
            let value: f64 = text
                .parse()
                .map_err(|_| format!("malformed number '{text}' at position {pos}"))?;
            if !value.is_finite() {
                return Err(format!("number '{text}' at position {pos} is out of range"));
            }
            i -= 1;
            Tok::Num(value)
        } else if c.is_alphabetic() || c == '_' {
            let start = i;
            while i + 1 < chars.len() && (chars[i + 1].is_alphanumeric() || chars[i + 1] == '_') {
                i += 1;
            }
            Tok::Ident(chars[start..=i].iter().collect())
        } else {
            match c {
                '+' | '-' | '*' | '/' | '^' => Tok::Op(c),
                '(' => Tok::LParen,
                ')' => Tok::RParen,
                ',' => Tok::Comma,
                _ => {
                    return Err(format!(
                        "unexpected character '{c}' at position {pos}; allowed are numbers, \
                         x, y, t, constants, functions, + - * / ^ ( ) and ','"
                    ))
                }
            }
        };
        out.push(Token { kind, pos });
        i += 1;
    }
    Ok(out)
}

/// A parsed formula: numbers, coordinates and `f64` operations.
#[derive(Debug, Clone)]
enum Ast {
    Num(f64),
    /// 0 = x, 1 = y, 2 = t.
    Var(usize),
    /// Unary minus or a function of one argument.
    Unary(Fn1, Box<Ast>),
    /// `+ - * / ^` or a function of two arguments.
    Binary(Fn2, Box<Ast>, Box<Ast>),
}

impl Ast {
    /// `f(a)`, computed now when `a` is a number.
    fn unary(f: Fn1, a: Ast) -> Ast {
        match a {
            Ast::Num(a) => Ast::Num(f(a)),
            a => Ast::Unary(f, Box::new(a)),
        }
    }

    /// `f(a, b)`, computed now when `a` and `b` are numbers.
    fn binary(f: Fn2, a: Ast, b: Ast) -> Ast {
        match (a, b) {
            (Ast::Num(a), Ast::Num(b)) => Ast::Num(f(a, b)),
            (a, b) => Ast::Binary(f, Box::new(a), Box::new(b)),
        }
    }

    /// The value at `xyt` = [x, y, t, z].
    fn eval(&self, xyt: &[f64; 4]) -> f64 {
        match self {
            Ast::Num(c) => *c,
            Ast::Var(i) => xyt[*i],
            Ast::Unary(f, a) => f(a.eval(xyt)),
            Ast::Binary(f, a, b) => f(a.eval(xyt), b.eval(xyt)),
        }
    }

    /// Sets `uses[i]` for every coordinate i that occurs.
    fn mark_variables(&self, uses: &mut [bool; 4]) {
        match self {
            Ast::Num(_) => {}
            Ast::Var(i) => uses[*i] = true,
            Ast::Unary(_, a) => a.mark_variables(uses),
            Ast::Binary(_, a, b) => {
                a.mark_variables(uses);
                b.mark_variables(uses);
            }
        }
    }
}

struct Parser<'a> {
    tokens: &'a [Token],
    pos: usize,
    depth: usize,
}

/// Binding power of prefix minus/plus: tighter than * and /, looser than ^.
const PREFIX_BP: u8 = 5;

fn infix_bp(op: char) -> (u8, u8) {
    match op {
        '+' | '-' => (1, 2),
        '*' | '/' => (3, 4),
        // Right-associative; the exponent may carry its own sign (2^-1).
        _ => (7, 6),
    }
}

impl Parser<'_> {
    fn end_pos(&self) -> usize {
        self.tokens.last().map_or(1, |t| t.pos + 1)
    }

    fn peek(&self) -> Option<&Tok> {
        self.tokens.get(self.pos).map(|t| &t.kind)
    }

    fn expr(&mut self, min_bp: u8) -> Result<Ast, String> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return Err(format!(
                "formula nested too deeply (more than {MAX_DEPTH} levels of parentheses, signs or powers)"
            ));
        }
        let mut lhs = match self.peek() {
            Some(Tok::Op('-')) => {
                self.pos += 1;
                Ast::unary(neg, self.expr(PREFIX_BP)?)
            }
            Some(Tok::Op('+')) => {
                self.pos += 1;
                self.expr(PREFIX_BP)?
            }
            _ => self.primary()?,
        };
        while let Some(Tok::Op(op)) = self.peek() {
            let op = *op;
            let (lbp, rbp) = infix_bp(op);
            if lbp < min_bp {
                break;
            }
            self.pos += 1;
            let rhs = self.expr(rbp)?;
            lhs = Ast::binary(operator(op), lhs, rhs);
        }
        self.depth -= 1;
        Ok(lhs)
    }

    fn primary(&mut self) -> Result<Ast, String> {
        let Some(tok) = self.tokens.get(self.pos) else {
            return Err(format!(
                "formula ends too early at position {}: expected a number, x, y, t, a function or '('",
                self.end_pos()
            ));
        };
        let pos = tok.pos;
        self.pos += 1;
        match &tok.kind {
            Tok::Num(v) => Ok(Ast::Num(*v)),
            Tok::LParen => {
                let inner = self.expr(0)?;
                self.expect_rparen(pos)?;
                Ok(inner)
            }
            Tok::Ident(name) => {
                let called = self.peek() == Some(&Tok::LParen);
                if called {
                    self.pos += 1;
                    return self.call(name, pos);
                }
                if let Some(i) = VARIABLES.iter().position(|v| v == name) {
                    return Ok(Ast::Var(i));
                }
                if let Some((_, v)) = CONSTANTS.iter().find(|(c, _)| c == name) {
                    return Ok(Ast::Num(*v));
                }
                if is_function(name) {
                    return Err(format!(
                        "function '{name}' at position {pos} needs parentheses: {name}(...)"
                    ));
                }
                Err(format!(
                    "unknown variable '{name}' at position {pos}: formulas may use only x, y, z, t \
                     (and the constants pi, e)"
                ))
            }
            other => Err(format!(
                "expected a number, x, y, t, a function or '(' at position {pos}, found {}",
                other.describe()
            )),
        }
    }

    fn expect_rparen(&mut self, open_pos: usize) -> Result<(), String> {
        match self.tokens.get(self.pos) {
            Some(Token {
                kind: Tok::RParen, ..
            }) => {
                self.pos += 1;
                Ok(())
            }
            Some(t) => Err(format!(
                "expected ')' (closing the '(' at position {open_pos}) at position {}, found {}",
                t.pos,
                t.kind.describe()
            )),
            None => Err(format!("missing ')' for the '(' at position {open_pos}")),
        }
    }

    /// A call `name(` has been read; parses the arguments and the closing parenthesis.
    fn call(&mut self, name: &str, pos: usize) -> Result<Ast, String> {
        let mut args = vec![self.expr(0)?];
        while self.peek() == Some(&Tok::Comma) {
            self.pos += 1;
            args.push(self.expr(0)?);
        }
        self.expect_rparen(pos + name.chars().count())?;
        let n = args.len();
        if let Some(&(_, f)) = FUNCTIONS.iter().find(|(f, _)| *f == name) {
            if n != 1 {
                return Err(format!(
                    "function '{name}' at position {pos} takes 1 argument, got {n}"
                ));
            }
            let a = args.pop().ok_or("internal error: no argument")?;
            return Ok(Ast::unary(f, a));
        }
        let Some(&(f_name, f)) = BINARY_FUNCTIONS.iter().find(|(f, _)| *f == name) else {
            let known: Vec<&str> = FUNCTIONS
                .iter()
                .map(|(f, _)| *f)
                .chain(BINARY_FUNCTIONS.iter().map(|(f, _)| *f))
                .collect();
            return Err(format!(
                "unknown function '{name}' at position {pos}; known functions: {}",
                known.join(", ")
            ));
        };
        if n < 2 || (f_name == "atan2" && n != 2) {
            let expected = if f_name == "atan2" { "2" } else { "2 or more" };
            return Err(format!(
                "function '{name}' at position {pos} takes {expected} arguments, got {n}"
            ));
        }
        // min(a, b, c) = min(min(a, b), c).
        let mut it = args.into_iter();
        let first = it.next().ok_or("internal error: no argument")?;
        Ok(it.fold(first, |acc, b| Ast::binary(f, acc, b)))
    }
}

fn is_function(name: &str) -> bool {
    FUNCTIONS.iter().any(|(f, _)| *f == name) || BINARY_FUNCTIONS.iter().any(|(f, _)| *f == name)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use proptest::test_runner::{RngAlgorithm, TestRng};
    use std::f64::consts::{E, PI};
    use std::hint::black_box;

    fn ev(src: &str, x: f64, y: f64, t: f64) -> f64 {
        Expr::parse(src)
            .unwrap_or_else(|e| panic!("{src}: {e}"))
            .eval(x, y, t)
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-12 * (1.0 + b.abs())
    }

    #[test]
    fn values_of_formulas() {
        let cases: &[(&str, f64)] = &[
            ("1 + 2*3", 7.0),
            ("-0.2*min(t/0.1,1)", -0.2 * (0.5f64 / 0.1).min(1.0)),
            ("max(x, y)", 3.0),
            ("min(x, y, t, -1)", -1.0),
            ("atan2(y, x)", 3.0f64.atan2(2.0)),
            ("sqrt(x^2 + y^2)", 13.0f64.sqrt()),
            ("exp(-x^2)", (-4.0f64).exp()),
            ("-x^2", -4.0),
            ("-2^2", -4.0),
            ("2^-1", 0.5),
            ("2^3^2", 512.0),
            ("(-x)^2", 4.0),
            ("x - y - t", 2.0 - 3.0 - 0.5),
            ("x / y / t", 2.0 / 3.0 / 0.5),
            ("1.5e-3*x", 3e-3),
            ("2E2 + .5 + 2.", 202.5),
            ("sin(pi*x/4) + cos(0)", 2.0),
            ("log(e) + ln(e^2) + log10(1000) + log2(8)", 9.0),
            (
                "abs(-3) + sign(-2) + floor(2.7) + ceil(2.2) + round(2.5)",
                3.0 - 1.0 + 2.0 + 3.0 + 3.0,
            ),
            ("- - x", 2.0),
            ("+x", 2.0),
            ("2*-x", -4.0),
            ("3 - -1", 4.0),
            ("π", std::f64::consts::PI),
            ("tanh(0) + sinh(0) + cosh(0)", 1.0),
        ];
        for &(src, want) in cases {
            let got = ev(src, 2.0, 3.0, 0.5);
            assert!(close(got, want), "{src}: got {got}, want {want}");
        }
    }

    #[test]
    fn variables_map_onto_x_y_t() {
        let only_t = Expr::parse("t").unwrap();
        assert_eq!(only_t.eval(7.0, 8.0, 9.0), 9.0);
        assert!(only_t.uses_t() && !only_t.uses_x() && !only_t.uses_y());

        let only_y = Expr::parse("10*y").unwrap();
        assert_eq!(only_y.eval(7.0, 8.0, 9.0), 80.0);
        assert!(only_y.uses_y() && !only_y.uses_x() && !only_y.uses_t());

        // The arguments are (x, y, t), whichever of them occur.
        let xt = Expr::parse("x - 2*t").unwrap();
        assert_eq!(xt.eval(7.0, 8.0, 1.0), 5.0);
        assert!(xt.uses_x() && xt.uses_t() && !xt.uses_y());

        let yx = Expr::parse("y - x").unwrap();
        assert_eq!(yx.eval(1.0, 5.0, 0.0), 4.0);

        let all = Expr::parse("100*x + 10*y + t").unwrap();
        assert_eq!(all.eval(1.0, 2.0, 3.0), 123.0);

        let none = Expr::parse("1/4").unwrap();
        assert_eq!(none.eval(1.0, 2.0, 3.0), 0.25);
        assert!(!none.uses_x() && !none.uses_y() && !none.uses_t());
        assert_eq!(none.source(), "1/4");
    }

    #[test]
    fn non_finite_values_are_returned_not_hidden() {
        assert!(ev("1/x", 0.0, 0.0, 0.0).is_infinite());
        assert!(ev("sqrt(x)", -1.0, 0.0, 0.0).is_nan());
    }

    #[test]
    fn unknown_variables_are_refused_by_name() {
        let err = Expr::parse("x + w").unwrap_err();
        assert!(err.contains("'w'") && err.contains("x, y, z, t"), "{err}");
        assert!(Expr::parse("x + z").unwrap().uses_z());
        assert!(Expr::parse("NaN").unwrap_err().contains("'NaN'"));
        assert!(Expr::parse("inf").unwrap_err().contains("'inf'"));
        assert!(Expr::parse("xy").unwrap_err().contains("'xy'"));
    }

    #[test]
    fn over_long_input_is_refused() {
        let long = "1+".repeat(500) + "1";
        assert!(long.len() > MAX_LEN);
        assert!(Expr::parse(&long).unwrap_err().contains("too long"));
        let ok = "1+".repeat(499) + "1";
        assert_eq!(ev(&ok, 0.0, 0.0, 0.0), 500.0);
    }

    #[test]
    fn syntax_errors_are_readable() {
        let cases: &[(&str, &str)] = &[
            ("", "ends too early"),
            ("2x", "write 2*x"),
            ("x*", "ends too early"),
            ("(x", "missing ')'"),
            ("x)", "unmatched ')'"),
            ("sin x", "needs parentheses"),
            ("foo(x)", "unknown function 'foo'"),
            ("sin(x, y)", "takes 1 argument"),
            ("min(x)", "2 or more"),
            ("atan2(x, y, t)", "takes 2 arguments"),
            ("x # y", "unexpected character '#'"),
            ("1e999", "out of range"),
            ("()", "found ')'"),
            ("1,2", "found ','"),
        ];
        for &(src, want) in cases {
            let err = Expr::parse(src).unwrap_err();
            assert!(err.contains(want), "{src:?}: {err:?} lacks {want:?}");
        }
        let deep = "(".repeat(100) + "x" + &")".repeat(100);
        assert!(Expr::parse(&deep)
            .unwrap_err()
            .contains("nested too deeply"));
    }

    #[test]
    fn expr_is_send_and_sync() {
        fn check<T: Send + Sync + Clone + fmt::Debug>() {}
        check::<Expr>();
    }

    /// `a^b`: `powf` on values the compiler cannot see, as in [`Expr::eval`] (with a literal
    /// exponent 2 the compiler would compute `x*x`, which can differ from `powf` in the last bit).
    fn pow(a: f64, b: f64) -> f64 {
        black_box(a).powf(black_box(b))
    }

    /// Formulas and the same computation written in Rust, operation for operation: `^` is
    /// `powf`, `-a^b` is `-(a^b)`, functions are the `f64` methods of their names.
    type Closed = fn(f64, f64, f64) -> f64;
    #[allow(clippy::neg_multiply)] // "-1*max(...)" is a multiplication in the formula too
    const FORMULAS: &[(&str, Closed)] = &[
        ("-0.2*min(t/0.1, 1)", |_, _, t| -0.2 * (t / 0.1).min(1.0)),
        ("x^2", |x, _, _| pow(x, 2.0)),
        ("-x^2 + 2^-1*y", |x, y, _| -pow(x, 2.0) + pow(2.0, -1.0) * y),
        ("x^y^t", |x, y, t| pow(x, pow(y, t))),
        ("x - y - t", |x, y, t| x - y - t),
        ("x / y / t", |x, y, t| x / y / t),
        ("0.1*sin(pi*x)*exp(-t) + atan2(y, x + 1)/10", |x, y, t| {
            0.1 * (PI * x).sin() * (-t).exp() + y.atan2(x + 1.0) / 10.0
        }),
        ("-0.2*min(t/0.1, 1) + 0.05*x^2 - 2^-3*y^3^0.5", |x, y, t| {
            -0.2 * (t / 0.1).min(1.0) + 0.05 * pow(x, 2.0) - pow(2.0, -3.0) * pow(y, pow(3.0, 0.5))
        }),
        ("-1 - 0.1*cos(2*pi*x) + abs(x - 1)/5", |x, _, _| {
            -1.0 - 0.1 * (2.0 * PI * x).cos() + (x - 1.0).abs() / 5.0
        }),
        (
            "-(x-1)^2/4 - 1 + tanh(t) - sqrt(x + 1)/10 + log(x + 2)/7",
            |x, _, t| {
                -pow(x - 1.0, 2.0) / 4.0 - 1.0 + t.tanh() - (x + 1.0).sqrt() / 10.0
                    + (x + 2.0).ln() / 7.0
            },
        ),
        (
            "-1*max(1, y, t) + cbrt(y)/3 + sign(y - 0.5)/9",
            |_, y, t| -1.0 * 1f64.max(y).max(t) + y.cbrt() / 3.0 + (y - 0.5).signum() / 9.0,
        ),
        (
            "-e^(-t)*cosh(y)/2 - floor(3*y)/7 + ceil(2*y)/11 + round(y)/13",
            |_, y, t| {
                -pow(E, -t) * y.cosh() / 2.0 - (3.0 * y).floor() / 7.0
                    + (2.0 * y).ceil() / 11.0
                    + y.round() / 13.0
            },
        ),
        (
            "0.0005*sinh(x)*asin(y/2) + log10(1+x)/1000 + log2(1+y)/1000",
            |x, y, _| {
                0.0005 * x.sinh() * (y / 2.0).asin()
                    + (1.0 + x).log10() / 1000.0
                    + (1.0 + y).log2() / 1000.0
            },
        ),
        (
            "1 - 0.3*exp(-((x-1)^2 + (y-0.5)^2)/0.05) + tan(x/4) + acos(y/3) + atan(x) + ln(y^2)",
            |x, y, _| {
                1.0 - 0.3 * (-(pow(x - 1.0, 2.0) + pow(y - 0.5, 2.0)) / 0.05).exp()
                    + (x / 4.0).tan()
                    + (y / 3.0).acos()
                    + x.atan()
                    + pow(y, 2.0).ln()
            },
        ),
        ("-1.4*min(t/0.25, 1)*(1 + 0.1*sin(pi*y))", |_, y, t| {
            -1.4 * (t / 0.25).min(1.0) * (1.0 + 0.1 * (PI * y).sin())
        }),
        ("-0.2 + -x^2/10 + 3e-2*x*y*t", |x, y, t| {
            -0.2 + -pow(x, 2.0) / 10.0 + 3e-2 * x * y * t
        }),
        ("- - 0.01*x", |x, _, _| -(-0.01) * x),
        (
            "-0.8*(1 - exp(-5*t))*(1 + 0.25*cos(pi*x/2))^2",
            |x, _, t| -0.8 * (1.0 - (-5.0 * t).exp()) * pow(1.0 + 0.25 * (PI * x / 2.0).cos(), 2.0),
        ),
        ("π*PI/pi + .5 + 2. + 1.5E+1", |_, _, _| {
            PI * PI / PI + 0.5 + 2.0 + 15.0
        }),
    ];

    /// Evaluation matches the Rust of each formula bit for bit at many random points, inside
    /// and outside the domain of its functions (NaN where Rust gives NaN).
    #[test]
    fn evaluation_is_the_rust_of_the_formula_bit_for_bit() {
        let mut rng = TestRng::from_seed(RngAlgorithm::ChaCha, &[7; 32]);
        for &(src, closed) in FORMULAS {
            let e = Expr::parse(src).unwrap_or_else(|e| panic!("{src}: {e}"));
            for _ in 0..2000 {
                let [x, y, t] = [
                    rng.random_range(-3.0..3.0),
                    rng.random_range(-3.0..3.0),
                    rng.random_range(0.0..2.0),
                ];
                let (got, want) = (e.eval(x, y, t), closed(x, y, t));
                assert!(
                    got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
                    "{src} at ({x}, {y}, {t}): {got} vs {want}"
                );
            }
        }
    }

    proptest! {
        /// Arbitrary text never panics the parser.
        #[test]
        fn parse_never_panics(s in ".{0,80}") {
            let _ = Expr::parse(&s);
        }

        #[test]
        fn parse_never_panics_on_formula_like_text(s in "[-+*/^(),.0-9eExyt pimnaxsqrtlog]{0,60}") {
            if let Ok(e) = Expr::parse(&s) {
                let _ = e.eval(0.5, 0.25, 1.0);
            }
        }
    }
}
