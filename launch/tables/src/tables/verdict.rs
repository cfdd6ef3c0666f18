//! A table's verdict: which of its cells reproduce the paper's value within the documented band
//! (docs/model.md, "Reproduction band") and which do not.

use serde::Serialize;

/// A cell reproduces the paper when `this / paper` lies within `1 ± BAND`.
pub const BAND: f64 = 0.25;

/// Where the band and the cells outside it are explained.
const WHY: &str = "docs/model.md, \"Reproduction band\"";

/// One cell of a table beside the paper's value.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Cell {
    /// The table's column, e.g. `proposed`.
    pub column: String,
    /// The row, e.g. `robot 1` or `small-fast`.
    pub row: String,
    /// This run's value over the paper's; `None` when this run's value is not finite.
    pub ratio: Option<f64>,
    pub within: bool,
}

impl Cell {
    /// The cell of `this` beside `paper`; `None` where the paper has no value.
    pub fn new(column: &str, row: String, this: f64, paper: Option<f64>) -> Option<Self> {
        let paper = paper?;
        let ratio = Some(this / paper).filter(|r| r.is_finite());
        Some(Self {
            column: column.to_string(),
            row,
            ratio,
            within: ratio.is_some_and(|r| (r - 1.0).abs() <= BAND),
        })
    }
}

/// The verdict over a table's cells, as its JSON holds it.
#[derive(Debug, Clone, Serialize)]
pub struct Verdict {
    pub band: f64,
    pub cells: Vec<Cell>,
    /// Why no cell has a paper value, said when there is none.
    #[serde(skip)]
    none: &'static str,
    /// The table was made with options other than the paper's calibration: its cells are
    /// judged against the paper all the same, and the line says so.
    pub other_calibration: bool,
    /// The cells are means over seeds.
    #[serde(skip)]
    on_means: bool,
}

impl Verdict {
    /// The verdict of `cells`; `none`: why there is no cell, when there is none.
    pub fn of(cells: Vec<Cell>, none: &'static str) -> Self {
        Self {
            band: BAND,
            cells,
            none,
            other_calibration: false,
            on_means: false,
        }
    }

    /// The same, for a table made with options other than the paper's calibration.
    pub fn other_calibration(mut self, other: bool) -> Self {
        self.other_calibration = other;
        self
    }

    /// The same, for cells that are means over seeds.
    pub fn on_means(mut self) -> Self {
        self.on_means = true;
        self
    }

    /// The line printed under the table: the cells within the band, per column, then those
    /// outside it with their ratio; where the paper has no value, says why.
    pub fn line(&self) -> String {
        if self.cells.is_empty() {
            return format!("No cell has a paper value to compare with: {}.", self.none);
        }
        let list = |within: bool| -> String {
            let mut columns: Vec<&str> = Vec::new();
            for c in self.cells.iter().filter(|c| c.within == within) {
                if !columns.contains(&c.column.as_str()) {
                    columns.push(&c.column);
                }
            }
            let per_column: Vec<String> = columns
                .iter()
                .map(|column| {
                    let rows: Vec<String> = self
                        .cells
                        .iter()
                        .filter(|c| c.within == within && c.column == *column)
                        .map(|c| match (within, c.ratio) {
                            (true, _) => c.row.clone(),
                            (false, Some(r)) => format!("{} ({r:.2}×)", c.row),
                            (false, None) => format!("{} (no finite value)", c.row),
                        })
                        .collect();
                    format!("{column} {}", rows.join(", "))
                })
                .collect();
            if per_column.is_empty() {
                "none".into()
            } else {
                per_column.join("; ")
            }
        };
        let inside = self.cells.iter().filter(|c| c.within).count();
        let caveat = if self.other_calibration {
            " This table was made with options other than the paper's calibration (above): a \
             cell outside the band may be the options'."
        } else {
            ""
        };
        format!(
            "Verdict{}: {inside} of {} cells within ±{:.0} % of the paper. Within: {}. Outside: {}. \
             Why the band, and why these cells: {WHY}.{caveat}",
            if self.on_means { " (on the means)" } else { "" },
            self.cells.len(),
            BAND * 100.0,
            list(true),
            list(false),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cell_is_within_the_band_on_its_ratio_and_a_missing_or_non_finite_value_is_outside() {
        let c = |this: f64| Cell::new("proposed", "robot 1".into(), this, Some(0.008));
        assert!(c(0.0086).expect("a paper value").within);
        assert!(c(0.0099).expect("a paper value").within);
        assert!(!c(0.0101).expect("a paper value").within);
        assert!(!c(0.0059).expect("a paper value").within);
        let nan = c(f64::NAN).expect("a paper value");
        assert!(!nan.within && nan.ratio.is_none());
        assert_eq!(Cell::new("proposed", "robot 5".into(), 0.01, None), None);
    }

    #[test]
    fn the_line_lists_each_column_within_and_outside_with_ratios() {
        let cells = vec![
            Cell::new("traditional", "robot 1".into(), 0.0187, Some(0.028)),
            Cell::new("traditional", "robot 2".into(), 0.0494, Some(0.041)),
            Cell::new("proposed", "robot 1".into(), 0.0086, Some(0.008)),
            Cell::new("proposed", "robot 2".into(), f64::INFINITY, Some(0.013)),
        ];
        let v = Verdict::of(cells.into_iter().flatten().collect(), "none");
        assert_eq!(
            v.line(),
            "Verdict: 2 of 4 cells within ±25 % of the paper. Within: traditional robot 2; \
             proposed robot 1. Outside: traditional robot 1 (0.67×); proposed robot 2 (no finite \
             value). Why the band, and why these cells: docs/model.md, \"Reproduction band\"."
        );
        assert_eq!(
            Verdict::of(Vec::new(), "robot 1 is not the paper's").line(),
            "No cell has a paper value to compare with: robot 1 is not the paper's."
        );
        let means = Verdict::of(v.cells.clone(), "none")
            .on_means()
            .other_calibration(true)
            .line();
        assert!(
            means.starts_with("Verdict (on the means): 2 of 4")
                && means.ends_with("a cell outside the band may be the options'."),
            "{means}"
        );
    }
}
