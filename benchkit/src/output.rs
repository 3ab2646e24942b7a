//! What a bench writes: `RESULT` lines on stdout and CSV files.

use std::fmt;
use std::path::Path;

/// One `RESULT <name> key=value …` line, the figures that scripts and docs pick out of a
/// bench's output.
#[derive(Clone, Debug, PartialEq)]
pub struct ResultLine {
    name: String,
    fields: Vec<(String, String)>,
}

impl ResultLine {
    /// A line with no fields yet; `name` is every word before them (e.g. `net.avatar`, or
    /// `methods.drop ispc_s2i4` when a label follows the name).
    pub fn new(name: impl Into<String>) -> ResultLine {
        ResultLine {
            name: name.into(),
            fields: Vec::new(),
        }
    }

    /// Appends `key=value`.
    pub fn field(mut self, key: &str, value: impl fmt::Display) -> ResultLine {
        self.fields.push((key.to_owned(), value.to_string()));
        self
    }

    /// Appends `key=value` with `decimals` digits after the point (an `f32` widened to `f64`
    /// is the same number, so it prints the same digits).
    pub fn fixed(self, key: &str, value: impl Into<f64>, decimals: usize) -> ResultLine {
        let value = value.into();
        self.field(key, format_args!("{value:.decimals$}"))
    }

    /// The fields in order, as written.
    pub fn fields(&self) -> &[(String, String)] {
        &self.fields
    }
}

impl fmt::Display for ResultLine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "RESULT {}", self.name)?;
        for (k, v) in &self.fields {
            write!(f, " {k}={v}")?;
        }
        Ok(())
    }
}

/// A CSV table built row by row under a fixed header. Cells are written as given, without
/// quoting: bench cells are numbers and plain labels.
#[derive(Clone, Debug)]
pub struct Csv {
    columns: usize,
    text: String,
}

impl Csv {
    /// A table with these column names.
    pub fn new(columns: &[&str]) -> Csv {
        Csv {
            columns: columns.len(),
            text: columns.join(",") + "\n",
        }
    }

    /// Appends a row.
    ///
    /// # Panics
    /// If the row does not have one cell per column: a bench bug that would shift the
    /// columns of every reader.
    pub fn row<I>(&mut self, cells: I)
    where
        I: IntoIterator,
        I::Item: fmt::Display,
    {
        let cells: Vec<String> = cells.into_iter().map(|c| c.to_string()).collect();
        assert_eq!(
            cells.len(),
            self.columns,
            "CSV row {cells:?} against {} columns",
            self.columns
        );
        self.text += &cells.join(",");
        self.text.push('\n');
    }

    /// The table so far, header first, one line per row.
    pub fn text(&self) -> &str {
        &self.text
    }

    /// Writes the table to `path`.
    pub fn write(&self, path: impl AsRef<Path>) -> std::io::Result<()> {
        std::fs::write(path, &self.text)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn result_line_format() {
        let l = ResultLine::new("net.avatar")
            .field("hz", 20)
            .fixed("bytes_per_s", 1234.56, 0)
            .fixed("p95_mm", 1.25, 2);
        assert_eq!(
            l.to_string(),
            "RESULT net.avatar hz=20 bytes_per_s=1235 p95_mm=1.25"
        );
        assert_eq!(ResultLine::new("a b").to_string(), "RESULT a b");
        assert_eq!(l.fields()[0], ("hz".to_owned(), "20".to_owned()));
    }

    #[test]
    fn csv_rows_follow_the_header() {
        let mut c = Csv::new(&["a", "b"]);
        c.row([1.5f32, 2.0]);
        c.row(["x".to_string(), format!("{:.2}", 0.5)]);
        assert_eq!(c.text(), "a,b\n1.5,2\nx,0.50\n");
    }

    #[test]
    #[should_panic(expected = "CSV row")]
    fn csv_refuses_a_short_row() {
        Csv::new(&["a", "b"]).row([1]);
    }
}
