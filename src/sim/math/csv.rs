//! RFC 4180 CSV text: a header, rows of cells, CRLF line ends; a cell is quoted when it holds a
//! comma, a quote or a line break. Numbers are written in Rust's shortest round-trip form (what
//! the JSON documents hold), missing values as empty cells.

use serde_json::Value;

/// A CSV document being written.
pub struct Csv {
    out: String,
}

impl Csv {
    /// A document with this header.
    pub fn new<'a>(header: impl IntoIterator<Item = &'a str>) -> Self {
        let mut csv = Self { out: String::new() };
        csv.row(header.into_iter().map(quoted));
        csv
    }

    /// Appends one row of already formatted cells (see [`quoted`], [`number`], [`cell`]).
    pub fn row(&mut self, cells: impl IntoIterator<Item = String>) {
        let cells: Vec<String> = cells.into_iter().collect();
        self.out.push_str(&cells.join(","));
        self.out.push_str("\r\n");
    }

    /// The text written so far: the header and every row, each ended by CRLF.
    pub fn finish(self) -> String {
        self.out
    }
}

/// A text cell, quoted when it needs to be.
pub fn quoted(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) { format!("\"{}\"", s.replace('"', "\"\"")) } else { s.to_string() }
}

/// A number cell; empty when missing.
pub fn number(x: Option<f64>) -> String {
    x.map(|v| v.to_string()).unwrap_or_default()
}

/// A JSON value as a cell: scalars as they are, null empty, objects and arrays as their JSON text.
pub fn cell(v: &Value) -> String {
    match v {
        Value::Null => String::new(),
        Value::String(s) => quoted(s),
        Value::Number(n) => n.to_string(),
        Value::Bool(b) => b.to_string(),
        other => quoted(&other.to_string()),
    }
}

/// A serialisable enum (or any value) as a cell, by its JSON form (`optimal_cv`, `fitted`).
pub fn json_cell<T: serde::Serialize>(value: &T) -> String {
    serde_json::to_value(value).map(|v| cell(&v)).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_are_quoted_only_when_needed_and_nulls_are_empty() {
        assert_eq!(cell(&Value::Null), "");
        assert_eq!(cell(&serde_json::json!("a,b")), "\"a,b\"");
        assert_eq!(
            cell(&serde_json::json!({ "kind": "spot", "a": 0.02 })),
            "\"{\"\"a\"\":0.02,\"\"kind\"\":\"\"spot\"\"}\""
        );
        assert_eq!(cell(&serde_json::json!(0.003)), "0.003");
        assert_eq!(quoted("plain"), "plain");
        assert_eq!(number(None), "");
        assert_eq!(number(Some(1e-5)), "0.00001");
        let mut csv = Csv::new(["a", "b,c"]);
        csv.row(["1".to_string(), quoted("x\"y")]);
        assert_eq!(csv.finish(), "a,\"b,c\"\r\n1,\"x\"\"y\"\r\n");
    }
}
