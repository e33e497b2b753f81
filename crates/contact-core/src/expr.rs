//! User formulas f(x, y, t) for loads and initial data: parsed once, evaluated many times.
//!
//! Evaluation is done by [exmex](https://docs.rs/exmex) (≈ 100 ns per call). Parsing is done
//! here first, by a small Pratt parser with the conventional grammar, and the result is handed
//! to exmex as a fully parenthesised string. Two reasons:
//!
//! - exmex's own grammar differs from the usual one in ways that silently change a load:
//!   its unary minus binds tighter than `^` (`-x^2` is `(-x)^2`, so `exp(-x^2)` grows instead
//!   of decaying) and `^` is left-associative (`2^3^2` is 64, not 512). Here `-x^2 = -(x^2)`,
//!   `2^-1 = 0.5` and `x^y^z = x^(y^z)`, as in every textbook and spreadsheet.
//! - its error messages ("we have 0 ops and 2 node") do not tell a user what to fix; ours name
//!   the position and the expected input, and unknown names are listed with the allowed ones.
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
//! `log` is the natural logarithm (as `ln`). `min` and `max` take two or more arguments,
//! `atan2(y, x)` exactly two.

use std::fmt;

use exmex::{Express, FlatEx};

/// Longest accepted formula, in characters (a guard for a public service, not a modelling limit).
pub const MAX_LEN: usize = 1000;

/// Deepest accepted nesting of parentheses, signs and powers.
const MAX_DEPTH: usize = 64;

/// Functions of one argument, as written in formulas, and exmex's name for each.
pub const FUNCTIONS: &[(&str, &str)] = &[
    ("abs", "abs"),
    ("sign", "signum"),
    ("signum", "signum"),
    ("sqrt", "sqrt"),
    ("cbrt", "cbrt"),
    ("exp", "exp"),
    ("ln", "ln"),
    ("log", "ln"),
    ("log2", "log2"),
    ("log10", "log10"),
    ("sin", "sin"),
    ("cos", "cos"),
    ("tan", "tan"),
    ("asin", "asin"),
    ("acos", "acos"),
    ("atan", "atan"),
    ("sinh", "sinh"),
    ("cosh", "cosh"),
    ("tanh", "tanh"),
    ("floor", "floor"),
    ("ceil", "ceil"),
    ("round", "round"),
];

/// Functions of two (min, max: two or more) arguments; exmex has them as binary operators.
const BINARY_FUNCTIONS: &[&str] = &["min", "max", "atan2"];

/// Named constants.
const CONSTANTS: &[(&str, f64)] = &[
    ("pi", std::f64::consts::PI),
    ("PI", std::f64::consts::PI),
    ("π", std::f64::consts::PI),
    ("e", std::f64::consts::E),
];

/// The coordinates a formula may use, in the order of [`Expr::eval`]'s arguments.
const VARIABLES: [&str; 3] = ["x", "y", "t"];

/// A parsed formula f(x, y, t).
#[derive(Clone)]
pub struct Expr {
    source: String,
    /// Boxed: exmex keeps up to 32 nodes inline (≈ 20 kB), which would make every
    /// `ScalarField` and `Problem` huge and overflow test-thread stacks in debug builds.
    flat: Box<FlatEx<f64>>,
    /// exmex binds its variables in alphabetical order of the names that occur (t, x, y);
    /// argument slot i of exmex receives coordinate `slots[i]` (0 = x, 1 = y, 2 = t).
    slots: [usize; 3],
    n_slots: usize,
    uses: [bool; 3],
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
        let ast = parser.expr(0)?;
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
        Expr::compile(src, &ast)
    }

    /// Hands a parse tree to exmex.
    fn compile(src: &str, ast: &Ast) -> Result<Expr, String> {
        let mut text = String::with_capacity(2 * src.len() + 8);
        ast.emit(&mut text);
        let flat = FlatEx::<f64>::parse(&text)
            .map(Box::new)
            .map_err(|e| format!("internal error: formula could not be compiled ({e})"))?;
        let mut slots = [0usize; 3];
        let mut uses = [false; 3];
        let names = flat.var_names();
        if names.len() > 3 {
            return Err("internal error: formula binds more than x, y, t".to_string());
        }
        for (slot, name) in names.iter().enumerate() {
            let Some(which) = VARIABLES.iter().position(|v| v == name) else {
                return Err(format!("internal error: unexpected variable '{name}'"));
            };
            slots[slot] = which;
            uses[which] = true;
        }
        let n_slots = names.len();
        Ok(Expr {
            source: src.to_string(),
            flat,
            slots,
            n_slots,
            uses,
        })
    }

    /// f(x, y, t). Does not allocate for formulas of up to 32 numbers and variables.
    #[inline]
    pub fn eval(&self, x: f64, y: f64, t: f64) -> f64 {
        let xyt = [x, y, t];
        let mut args = [0.0f64; 3];
        for (arg, &which) in args.iter_mut().zip(&self.slots).take(self.n_slots) {
            *arg = xyt[which];
        }
        self.flat.eval(&args[..self.n_slots]).unwrap_or(f64::NAN)
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

#[derive(Debug, Clone)]
enum Ast {
    Num(f64),
    /// 0 = x, 1 = y, 2 = t.
    Var(usize),
    Neg(Box<Ast>),
    /// One of + - * / ^.
    Bin(char, Box<Ast>, Box<Ast>),
    /// A one-argument function, by its exmex name.
    Call1(&'static str, Box<Ast>),
    /// min, max or atan2 (exmex binary operators).
    Call2(&'static str, Box<Ast>, Box<Ast>),
}

impl Ast {
    /// Fully parenthesised text for exmex, so that its operator priorities never matter.
    fn emit(&self, out: &mut String) {
        match self {
            // Display of f64 is the shortest round-trip decimal, without an exponent (which
            // exmex's number literals do not support).
            Ast::Num(v) => out.push_str(&format!("({v})")),
            Ast::Var(i) => out.push_str(VARIABLES[*i]),
            Ast::Neg(a) => {
                out.push_str("(-(");
                a.emit(out);
                out.push_str("))");
            }
            Ast::Bin(op, a, b) => {
                out.push_str("((");
                a.emit(out);
                out.push(')');
                out.push(*op);
                out.push('(');
                b.emit(out);
                out.push_str("))");
            }
            Ast::Call1(f, a) => {
                out.push('(');
                out.push_str(f);
                out.push('(');
                a.emit(out);
                out.push_str("))");
            }
            Ast::Call2(f, a, b) => {
                out.push_str("((");
                a.emit(out);
                out.push(')');
                out.push_str(f);
                out.push('(');
                b.emit(out);
                out.push_str("))");
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
                Ast::Neg(Box::new(self.expr(PREFIX_BP)?))
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
            lhs = Ast::Bin(op, Box::new(lhs), Box::new(rhs));
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
                    "unknown variable '{name}' at position {pos}: formulas may use only x, y, t \
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
        if let Some((_, exmex_name)) = FUNCTIONS.iter().find(|(f, _)| *f == name) {
            if n != 1 {
                return Err(format!(
                    "function '{name}' at position {pos} takes 1 argument, got {n}"
                ));
            }
            let a = args
                .pop()
                .map(Box::new)
                .ok_or("internal error: no argument")?;
            return Ok(Ast::Call1(exmex_name, a));
        }
        let Some(&f) = BINARY_FUNCTIONS.iter().find(|f| **f == name) else {
            let known: Vec<&str> = FUNCTIONS
                .iter()
                .map(|(f, _)| *f)
                .chain(BINARY_FUNCTIONS.iter().copied())
                .collect();
            return Err(format!(
                "unknown function '{name}' at position {pos}; known functions: {}",
                known.join(", ")
            ));
        };
        if n < 2 || (f == "atan2" && n != 2) {
            let expected = if f == "atan2" { "2" } else { "2 or more" };
            return Err(format!(
                "function '{name}' at position {pos} takes {expected} arguments, got {n}"
            ));
        }
        // min(a, b, c) = min(min(a, b), c).
        let mut it = args.into_iter();
        let first = it.next().ok_or("internal error: no argument")?;
        Ok(it.fold(first, |acc, b| Ast::Call2(f, Box::new(acc), Box::new(b))))
    }
}

fn is_function(name: &str) -> bool {
    FUNCTIONS.iter().any(|(f, _)| *f == name) || BINARY_FUNCTIONS.contains(&name)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

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

        // Alphabetical order of exmex would be (t, x); our arguments are (x, y, t).
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
        let err = Expr::parse("x + z").unwrap_err();
        assert!(err.contains("'z'") && err.contains("x, y, t"), "{err}");
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

    /// Reference evaluation of the parse tree (the oracle for exmex's evaluation).
    fn oracle(a: &Ast, v: [f64; 3]) -> f64 {
        match a {
            Ast::Num(c) => *c,
            Ast::Var(i) => v[*i],
            Ast::Neg(a) => -oracle(a, v),
            Ast::Bin(op, a, b) => {
                let (a, b) = (oracle(a, v), oracle(b, v));
                match op {
                    '+' => a + b,
                    '-' => a - b,
                    '*' => a * b,
                    '/' => a / b,
                    _ => a.powf(b),
                }
            }
            Ast::Call1(f, a) => {
                let a = oracle(a, v);
                match *f {
                    "abs" => a.abs(),
                    "signum" => a.signum(),
                    "sqrt" => a.sqrt(),
                    "cbrt" => a.cbrt(),
                    "exp" => a.exp(),
                    "ln" => a.ln(),
                    "log2" => a.log2(),
                    "log10" => a.log10(),
                    "sin" => a.sin(),
                    "cos" => a.cos(),
                    "tan" => a.tan(),
                    "asin" => a.asin(),
                    "acos" => a.acos(),
                    "atan" => a.atan(),
                    "sinh" => a.sinh(),
                    "cosh" => a.cosh(),
                    "tanh" => a.tanh(),
                    "floor" => a.floor(),
                    "ceil" => a.ceil(),
                    "round" => a.round(),
                    other => panic!("oracle lacks {other}"),
                }
            }
            Ast::Call2(f, a, b) => {
                let (a, b) = (oracle(a, v), oracle(b, v));
                match *f {
                    "min" => a.min(b),
                    "max" => a.max(b),
                    _ => a.atan2(b),
                }
            }
        }
    }

    fn ast_strategy() -> impl Strategy<Value = Ast> {
        let leaf = prop_oneof![
            (0.0f64..10.0).prop_map(Ast::Num),
            (0usize..3).prop_map(Ast::Var),
        ];
        leaf.prop_recursive(5, 40, 2, |inner| {
            prop_oneof![
                inner.clone().prop_map(|a| Ast::Neg(Box::new(a))),
                (
                    prop::sample::select(vec!['+', '-', '*', '/', '^']),
                    inner.clone(),
                    inner.clone()
                )
                    .prop_map(|(op, a, b)| Ast::Bin(op, Box::new(a), Box::new(b))),
                (
                    prop::sample::select(FUNCTIONS.iter().map(|f| f.1).collect::<Vec<_>>()),
                    inner.clone()
                )
                    .prop_map(|(f, a)| Ast::Call1(f, Box::new(a))),
                (
                    prop::sample::select(BINARY_FUNCTIONS.to_vec()),
                    inner.clone(),
                    inner
                )
                    .prop_map(|(f, a, b)| Ast::Call2(f, Box::new(a), Box::new(b))),
            ]
        })
    }

    proptest! {
        /// exmex, fed our parenthesised text, computes exactly what the parse tree says.
        #[test]
        fn exmex_agrees_with_the_parse_tree(ast in ast_strategy(), x in -3.0f64..3.0, y in -3.0f64..3.0, t in 0.0f64..2.0) {
            let mut text = String::new();
            ast.emit(&mut text);
            let e = Expr::compile("", &ast).map_err(|e| TestCaseError::fail(format!("{text}: {e}")))?;
            let got = e.eval(x, y, t);
            let want = oracle(&ast, [x, y, t]);
            prop_assert!(got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()) || close(got, want),
                "{}: exmex {} vs tree {}", text, got, want);
        }

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
