//! The `${...}` variables of the SLA control-file standard (schema v5): a setting may be
//! `"${name}"` or an arithmetic expression over the file's `Variables`
//! (`"${base_ms * 1.5}"`), keeping the value's type, or text with expressions inside
//! (`"slice_${n}.png"`). The standard's own tools evaluate them with Python's simpleeval;
//! this reads numbers, names, `+ - * / // % **`, unary minus and parentheses, nested at
//! most 100 levels (parentheses, signs and powers; deeper is an error, never a stack
//! overflow).

use serde_json::{Map, Number, Value};

/// A value during evaluation: a number (integer when every step kept it whole), text or a
/// truth value.
#[derive(Debug, Clone, PartialEq)]
enum V {
    Num(f64, bool),
    Text(String),
    Bool(bool),
}

impl V {
    fn of(v: &Value) -> Option<V> {
        match v {
            Value::Number(n) => Some(V::Num(n.as_f64()?, n.is_i64() || n.is_u64())),
            Value::String(s) => Some(V::Text(s.clone())),
            Value::Bool(b) => Some(V::Bool(*b)),
            _ => None,
        }
    }

    fn into_json(self) -> Value {
        match self {
            V::Num(x, true) if x.abs() < 9e15 => Value::Number(Number::from(x as i64)),
            V::Num(x, _) => Number::from_f64(x).map_or(Value::Null, Value::Number),
            V::Text(s) => Value::String(s),
            V::Bool(b) => Value::Bool(b),
        }
    }

    /// As Python's `str()` would print it inside text.
    fn text(&self) -> String {
        match self {
            V::Num(x, true) => format!("{}", *x as i64),
            V::Num(x, false) if x.fract() == 0.0 && x.abs() < 1e16 => format!("{x:.1}"),
            V::Num(x, false) => format!("{x}"),
            V::Text(s) => s.clone(),
            V::Bool(b) => if *b { "True" } else { "False" }.into(),
        }
    }
}

/// Deepest nesting of parentheses, unary signs and powers an expression may have (Python
/// refuses deeper nesting too); the parser recurses once a level.
const MAX_DEPTH: usize = 100;

/// What an expansion may still make, bytes: the text of every string it produces, one a
/// value otherwise. Text interpolation repeats what it names, so without a bound a small
/// file could ask for any amount of memory.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Budget {
    left: u64,
    of: u64,
}

impl Budget {
    /// A budget of `bytes`.
    pub(crate) fn new(bytes: u64) -> Budget {
        Budget {
            left: bytes,
            of: bytes,
        }
    }

    /// Takes `n` bytes, or says the expansion is too large.
    pub(crate) fn take(&mut self, n: u64) -> Result<(), String> {
        if n > self.left {
            return Err(format!(
                "the settings expand to more than {} bytes",
                self.of
            ));
        }
        self.left -= n;
        Ok(())
    }
}

struct Parser<'a> {
    s: &'a [u8],
    i: usize,
    vars: &'a Map<String, Value>,
    /// Longest text a step may make, bytes.
    max_text: u64,
    /// Levels of parentheses, signs and powers entered and not left.
    depth: usize,
}

impl Parser<'_> {
    fn skip(&mut self) {
        while self.s.get(self.i).is_some_and(|c| c.is_ascii_whitespace()) {
            self.i += 1;
        }
    }

    fn eat(&mut self, t: &str) -> bool {
        self.skip();
        if self.s[self.i..].starts_with(t.as_bytes()) {
            self.i += t.len();
            true
        } else {
            false
        }
    }

    fn num(v: V) -> Result<(f64, bool), String> {
        match v {
            V::Num(x, i) => Ok((x, i)),
            V::Bool(b) => Ok((f64::from(u8::from(b)), true)),
            V::Text(t) => Err(format!("{t:?} is text, not a number")),
        }
    }

    fn sum(&mut self) -> Result<V, String> {
        let mut a = self.product()?;
        loop {
            let op = if self.eat("+") {
                '+'
            } else if self.eat("-") {
                '-'
            } else {
                return Ok(a);
            };
            let b = self.product()?;
            a = match (a, b, op) {
                (V::Text(x), V::Text(y), '+') => {
                    if (x.len() + y.len()) as u64 > self.max_text {
                        return Err(format!(
                            "the text passes the {} bytes the settings may expand to",
                            self.max_text
                        ));
                    }
                    V::Text(x + &y)
                }
                (a, b, op) => {
                    let ((x, xi), (y, yi)) = (Self::num(a)?, Self::num(b)?);
                    V::Num(if op == '+' { x + y } else { x - y }, xi && yi)
                }
            };
        }
    }

    fn product(&mut self) -> Result<V, String> {
        let mut a = self.power()?;
        loop {
            let op = if self.eat("//") {
                "//"
            } else if self.eat("*") {
                "*"
            } else if self.eat("/") {
                "/"
            } else if self.eat("%") {
                "%"
            } else {
                return Ok(a);
            };
            let ((x, xi), (y, yi)) = (Self::num(a)?, Self::num(self.power()?)?);
            if op != "*" && y == 0.0 {
                return Err("division by zero".into());
            }
            a = match op {
                "*" => V::Num(x * y, xi && yi),
                "/" => V::Num(x / y, false),
                "//" => V::Num((x / y).floor(), xi && yi),
                _ => V::Num(x - y * (x / y).floor(), xi && yi),
            };
        }
    }

    /// `f` one level deeper, refused past [`MAX_DEPTH`].
    fn nested(&mut self, f: fn(&mut Self) -> Result<V, String>) -> Result<V, String> {
        if self.depth >= MAX_DEPTH {
            return Err(format!("nested deeper than {MAX_DEPTH} levels"));
        }
        self.depth += 1;
        let v = f(self);
        self.depth -= 1;
        v
    }

    fn power(&mut self) -> Result<V, String> {
        let a = self.unary()?;
        if self.eat("**") {
            let ((x, xi), (y, yi)) = (Self::num(a)?, Self::num(self.nested(Self::power)?)?);
            return Ok(V::Num(x.powf(y), xi && yi && y >= 0.0));
        }
        Ok(a)
    }

    fn unary(&mut self) -> Result<V, String> {
        if self.eat("-") {
            let (x, i) = Self::num(self.nested(Self::unary)?)?;
            return Ok(V::Num(-x, i));
        }
        if self.eat("+") {
            return self.nested(Self::unary);
        }
        self.atom()
    }

    fn atom(&mut self) -> Result<V, String> {
        self.skip();
        if self.eat("(") {
            let v = self.nested(Self::sum)?;
            if !self.eat(")") {
                return Err("a `(` is not closed".into());
            }
            return Ok(v);
        }
        let start = self.i;
        let c = *self.s.get(self.i).ok_or("the expression ends early")?;
        if c.is_ascii_digit() || c == b'.' {
            while self
                .s
                .get(self.i)
                .is_some_and(|c| c.is_ascii_digit() || *c == b'.')
            {
                self.i += 1;
            }
            if self.s.get(self.i).is_some_and(|c| *c == b'e' || *c == b'E') {
                self.i += 1;
                if self.s.get(self.i).is_some_and(|c| *c == b'+' || *c == b'-') {
                    self.i += 1;
                }
                while self.s.get(self.i).is_some_and(u8::is_ascii_digit) {
                    self.i += 1;
                }
            }
            let t = std::str::from_utf8(&self.s[start..self.i]).unwrap_or_default();
            let x: f64 = t.parse().map_err(|_| format!("{t:?} is not a number"))?;
            return Ok(V::Num(x, !t.contains(['.', 'e', 'E'])));
        }
        if c.is_ascii_alphabetic() || c == b'_' {
            while self
                .s
                .get(self.i)
                .is_some_and(|c| c.is_ascii_alphanumeric() || *c == b'_')
            {
                self.i += 1;
            }
            let name = std::str::from_utf8(&self.s[start..self.i]).unwrap_or_default();
            return match name {
                "True" => Ok(V::Bool(true)),
                "False" => Ok(V::Bool(false)),
                _ => self
                    .vars
                    .get(name)
                    .and_then(V::of)
                    .ok_or_else(|| format!("`{name}` is not a variable")),
            };
        }
        Err(format!("unexpected {:?}", c as char))
    }
}

/// The value of expression `e` over `vars`, its text at most `max_text` bytes.
fn eval(e: &str, vars: &Map<String, Value>, max_text: u64) -> Result<V, String> {
    let mut p = Parser {
        s: e.as_bytes(),
        i: 0,
        vars,
        max_text,
        depth: 0,
    };
    let v = p.sum()?;
    p.skip();
    if p.i != p.s.len() {
        return Err(format!("cannot read {:?}", &e[p.i..]));
    }
    Ok(v)
}

/// `v` with every `${...}` in its strings evaluated over `vars` (errors name the text),
/// what it makes taken from `budget`.
pub(crate) fn resolve(
    v: &Value,
    vars: &Map<String, Value>,
    budget: &mut Budget,
) -> Result<Value, String> {
    Ok(match v {
        Value::Object(m) => {
            budget.take(1)?;
            Value::Object(
                m.iter()
                    .map(|(k, v)| {
                        budget.take(k.len() as u64)?;
                        Ok((k.clone(), resolve(v, vars, budget)?))
                    })
                    .collect::<Result<_, String>>()?,
            )
        }
        Value::Array(a) => {
            budget.take(1)?;
            Value::Array(
                a.iter()
                    .map(|v| resolve(v, vars, budget))
                    .collect::<Result<_, _>>()?,
            )
        }
        Value::String(s) if s.contains("${") => {
            let bad = |m: String| format!("{s:?}: {m}");
            let t = s.trim();
            if t.starts_with("${") && t.ends_with('}') && t[2..].find('}') == Some(t.len() - 3) {
                let v = eval(&t[2..t.len() - 1], vars, budget.left).map_err(bad)?;
                budget.take(match &v {
                    V::Text(x) => x.len() as u64,
                    _ => 1,
                })?;
                return Ok(v.into_json());
            }
            let mut out = String::new();
            let mut rest = s.as_str();
            while let Some(a) = rest.find("${") {
                out.push_str(&rest[..a]);
                let b = rest[a..]
                    .find('}')
                    .ok_or_else(|| bad("a `${` is not closed".into()))?;
                let piece = eval(&rest[a + 2..a + b], vars, budget.left)
                    .map_err(bad)?
                    .text();
                budget.take((a + piece.len()) as u64)?;
                out.push_str(&piece);
                rest = &rest[a + b + 1..];
            }
            budget.take(rest.len() as u64)?;
            out.push_str(rest);
            Value::String(out)
        }
        Value::String(s) => {
            budget.take(s.len() as u64)?;
            v.clone()
        }
        other => {
            budget.take(1)?;
            other.clone()
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn eval(v: Value, vars: &Map<String, Value>) -> std::result::Result<Value, String> {
        resolve(&v, vars, &mut Budget::new(1 << 20))
    }

    #[test]
    fn expressions_keep_their_type_and_text_interpolates() {
        let vars = json!({"n": 3, "t": 400, "f": 1.5, "dir": "slices", "on": true});
        let vars = vars.as_object().unwrap();
        let r = |v: Value| eval(v, vars).unwrap();
        assert_eq!(r(json!("${n}")), json!(3));
        assert_eq!(r(json!("${t * f}")), json!(600.0));
        assert_eq!(r(json!("${(n + 1) * 2 - -1}")), json!(9));
        assert_eq!(r(json!("${t / 8}")), json!(50.0));
        assert_eq!(r(json!("${7 // 2 + 7 % 2 + 2 ** 3}")), json!(12));
        assert_eq!(r(json!("${on}")), json!(true));
        assert_eq!(r(json!("img_${n}_${f}.png")), json!("img_3_1.5.png"));
        assert_eq!(r(json!({"a": ["${n}", 2, "x"]})), json!({"a": [3, 2, "x"]}));
        for bad in ["${m}", "${n +}", "${(n}", "${n / 0}", "${dir * 2}", "x ${n"] {
            assert!(eval(json!(bad), vars).is_err(), "{bad}");
        }
    }

    #[test]
    fn deep_nesting_is_refused_without_exhausting_the_stack() {
        let vars = Map::new();
        let deep = |open: &str, close: &str| {
            format!("${{{}1{}}}", open.repeat(100_000), close.repeat(100_000))
        };
        for e in [
            deep("(", ")"),
            deep("-", ""),
            format!("${{2{}}}", "**2".repeat(100_000)),
        ] {
            let err = eval(json!(e), &vars).unwrap_err();
            assert!(
                err.contains("nested deeper than 100 levels"),
                "{}",
                &err[err.len() - 60..]
            );
        }
        // Within the bound it evaluates.
        let within = deep("(", ")")
            .replace(&"(".repeat(99_950), "")
            .replace(&")".repeat(99_950), "");
        assert_eq!(eval(json!(within), &vars).unwrap(), json!(1));
        // A long flat expression is no nesting.
        let flat = format!("${{0{}}}", "+1".repeat(100_000));
        assert_eq!(eval(json!(flat), &vars).unwrap(), json!(100_000));
    }
}
