//! The report toolkit every tool shares: SVG plots ([`plot`]), Markdown tables ([`Table`]) and the
//! physical constants the tools use. Output folders are written by [`crate::output`].

pub mod plot;

/// 0 °C in kelvin: the FMU speaks kelvin, reports speak °C.
pub const ZERO_CELSIUS: f64 = 273.15;
/// Standard gravity, m/s² (CGPM 1901).
pub const STANDARD_GRAVITY: f64 = 9.80665;

/// A Markdown table built row by row; cells are plain text (pipes are escaped).
pub struct Table {
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

impl Table {
    pub fn new<S: AsRef<str>>(header: &[S]) -> Table {
        Table { header: header.iter().map(|h| h.as_ref().to_string()).collect(), rows: Vec::new() }
    }

    /// Appends a row; missing cells are left empty, extra cells are an error of the caller.
    pub fn row<S: AsRef<str>>(&mut self, cells: &[S]) -> &mut Table {
        assert!(cells.len() <= self.header.len(), "a row has more cells than the header");
        self.rows.push(cells.iter().map(|c| c.as_ref().replace('|', "\\|")).collect());
        self
    }

    pub fn render(&self) -> String {
        let line = |cells: &[String]| {
            let mut l = String::from("|");
            for i in 0..self.header.len() {
                l.push(' ');
                l.push_str(cells.get(i).map_or("", String::as_str));
                l.push_str(" |");
            }
            l.push('\n');
            l
        };
        let mut s = line(&self.header);
        s.push('|');
        s.push_str(&"---|".repeat(self.header.len()));
        s.push('\n');
        for r in &self.rows {
            s.push_str(&line(r));
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::Table;

    #[test]
    fn a_table_renders_as_markdown_with_escaped_pipes_and_padded_rows() {
        let mut t = Table::new(&["a", "b"]);
        t.row(&["1", "x|y"]).row(&["2"]);
        assert_eq!(t.render(), "| a | b |\n|---|---|\n| 1 | x\\|y |\n| 2 |  |\n");
    }
}
