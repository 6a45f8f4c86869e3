//! A table a part produced and how one is cut out of a report: the book's unit, apart from the
//! page it goes into, so `report` can make tables without importing the book that writes them.

/// A table a part produced, for the book.
#[derive(Clone, Debug)]
pub struct Table {
    pub name: &'static str,
    /// When it was measured (`YYYY-MM-DD HH:MM UTC`).
    pub date: String,
    /// How much was measured ("40 rounds × 5000 round trips per transport"), if the part says.
    pub detail: Option<String>,
    /// The markdown table itself.
    pub markdown: String,
}

impl Table {
    /// The block's text: the run line, then the table.
    pub(super) fn block(&self, machine: &str, command: &str) -> String {
        let detail = self
            .detail
            .as_ref()
            .map_or(String::new(), |d| format!("; {d}"));
        format!(
            "Run: {} on {machine}{detail}; `{command}`.\n\n{}",
            self.date,
            self.markdown.trim()
        )
    }
}

/// The markdown tables in a piece of a report, in order: each a run of lines that start with `|`.
pub fn tables_in(markdown: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut current = String::new();
    for line in markdown.lines() {
        if line.trim_start().starts_with('|') {
            current.push_str(line.trim());
            current.push('\n');
        } else if !current.is_empty() {
            out.push(std::mem::take(&mut current));
        }
    }
    if !current.is_empty() {
        out.push(current);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tables_are_cut_out_of_a_report_in_order() {
        let md =
            "## T\n\ntext | not a table\n\n| a | b |\n|---|---|\n| 1 | 2 |\n\n- x\n| c |\n|---|\n";
        assert_eq!(
            tables_in(md),
            ["| a | b |\n|---|---|\n| 1 | 2 |\n", "| c |\n|---|\n"]
        );
        assert!(tables_in("no table\n").is_empty());
    }
}
