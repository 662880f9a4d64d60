//! Weave patterns as tiles of cells, and the per-cell diffusion tensors of seed §2.2.1.
//!
//! # Cells and orientation
//!
//! A fabric is a periodic tile of [`Cell`]s: warp, weft (each *up*, on the face, or *down*,
//! on the back) and gap. The tile's `x` axis is the **weft** direction (`u`: weft yarns run
//! left–right), its `y` axis the **warp** direction (`v`: warp yarns run bottom–top). Cells
//! are stored row-major with row 0 at the bottom (`y = 0`); a text grid ([`Tile::parse`])
//! lists the top row first, as it looks on screen.
//!
//! # Built-in weaves
//!
//! A weave is given by its *draft*: for warp end `i` (column) and weft pick `j` (row),
//! whether the warp passes over the weft at that crossing. The built-ins ([`Weave`]):
//!
//! | weave     | repeat | warp over weft at crossing `(i, j)`                        |
//! |-----------|--------|------------------------------------------------------------|
//! | `Plain`   | 2×2    | `(i + j) mod 2 = 0`                                        |
//! | `Twill21` | 3×3    | `(j − i) mod 3 < 2` (over 2, under 1, stepping right)      |
//! | `Twill31` | 4×4    | `(j − i) mod 4 < 3` (over 3, under 1)                      |
//! | `Satin5`  | 5×5    | `(j − 2i) mod 5 ≠ 0` (warp-faced, move number 2)           |
//! | `Basket`  | 4×4    | `(⌊i/2⌋ + ⌊j/2⌋) mod 2 = 0` (2×2 hopsack)                  |
//!
//! [`Tile::builtin`] turns a draft into cells in one of two layouts:
//!
//! - `gaps = false`: one cell per crossing, showing the yarn on top (`W` where the warp is
//!   over, `F` where the weft is). The yarn underneath is implied.
//! - `gaps = true` (the three-cell model of the seed, after Morimoto et al.): each crossing
//!   becomes a 2×2 block — the crossing cell (as above) at `(2i, 2j)`, the weft running on
//!   to the next warp end at `(2i+1, 2j)`, the warp running on to the next pick at
//!   `(2i, 2j+1)`, and the open gap between yarns at `(2i+1, 2j+1)`. A yarn segment between
//!   two crossings is *up* when the yarn is on the face at either end of it (it is seen
//!   from the face over at least half its length), *down* when it is under at both ends.
//!
//! # From cells to tensors (seed §2.2.1)
//!
//! Each pair of edge-adjacent cells has a permeability coefficient `D` from a
//! [`PairCoefficients`] table (default: the seed's values), and a cell's tensor averages its
//! four boundary coefficients,
//!
//! ```text
//! S = ½ [ D_left + D_right, 0 ; 0, D_top + D_bottom ],
//! ```
//!
//! with `D_left` the coefficient of the pair (this cell, its left neighbour), neighbours
//! taken periodically (the tile repeats). `S` is diagonal: cells carry no preferred
//! direction other than the weave axes.
//!
//! **Which coefficient a pair gets.** The Weisz–Zollinger model the seed cites has five
//! kinds of connectivity; the seed's table has six coefficients keyed by the cell kinds.
//! Our reading, where "layer" is a cell's up/down and a yarn is continuous along its own
//! direction (warp along `y`, weft along `x`):
//!
//! | pair of cells                                   | W–Z kind                        | coefficient |
//! |-------------------------------------------------|---------------------------------|-------------|
//! | gap – gap                                        | (d) gap and gap                 | `gap_gap`   |
//! | gap – warp, gap – weft (either layer)            | (c) fiber and gap               | `gap_warp`, `gap_weft` |
//! | warp – warp along `y` (the same warp yarn, even where it dives) | (e) parallel fibers | `warp_warp` |
//! | warp – warp along `x`, same layer                | (e) parallel fibers, same layer | `warp_warp` |
//! | weft – weft along `x` (the same weft yarn)       | (e) parallel fibers             | `weft_weft` |
//! | weft – weft along `y`, same layer                | (e) parallel fibers, same layer | `weft_weft` |
//! | warp – weft, same layer                          | (b) perpendicular, same layer   | `weft_warp` |
//! | warp – weft, different layers (a crossing)       | (a) fibers in different layers  | `weft_warp` |
//! | warp – warp along `x` / weft – weft along `y`, different layers | (a) different layers | `weft_warp` |
//!
//! The seed's table has no separate value for (a): the only contact between the face and the
//! back of a woven fabric is a warp–weft crossing, so we use its warp–weft coefficient for
//! every pair in different layers. Up/down therefore matters exactly where two neighbouring
//! parallel yarns lie in different layers (e.g. `W` beside `w`): they do not touch each other
//! directly, only through the perpendicular yarn they cross.

use std::fmt;

use super::Tensor2;
use crate::error::WeaveError;

/// One cell of a weave tile.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Cell {
    /// Open space between yarns.
    Gap,
    /// A warp yarn (runs along `y`); `up` = on the face of the fabric.
    Warp {
        /// On the face of the fabric (else on its back).
        up: bool,
    },
    /// A weft yarn (runs along `x`); `up` = on the face of the fabric.
    Weft {
        /// On the face of the fabric (else on its back).
        up: bool,
    },
}

impl Cell {
    /// The text-grid character: `W` warp up, `w` warp down, `F` weft up, `f` weft down,
    /// `.` gap.
    pub fn to_char(self) -> char {
        match self {
            Cell::Gap => '.',
            Cell::Warp { up: true } => 'W',
            Cell::Warp { up: false } => 'w',
            Cell::Weft { up: true } => 'F',
            Cell::Weft { up: false } => 'f',
        }
    }

    /// Inverse of [`Cell::to_char`].
    pub(crate) fn from_char(c: char) -> Option<Cell> {
        Some(match c {
            '.' => Cell::Gap,
            'W' => Cell::Warp { up: true },
            'w' => Cell::Warp { up: false },
            'F' => Cell::Weft { up: true },
            'f' => Cell::Weft { up: false },
            _ => return None,
        })
    }
}

/// The built-in weaves (see the module table for their drafts).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Weave {
    /// Plain (tabby): over one, under one.
    Plain,
    /// Twill 2/1: over two, under one, stepping right.
    Twill21,
    /// Twill 3/1: over three, under one.
    Twill31,
    /// Five-harness satin (warp-faced, move number 2).
    Satin5,
    /// Basket (2×2 hopsack).
    Basket,
}

impl Weave {
    /// Every built-in weave, in the order above.
    pub const ALL: [Weave; 5] = [
        Weave::Plain,
        Weave::Twill21,
        Weave::Twill31,
        Weave::Satin5,
        Weave::Basket,
    ];

    /// Side of the draft's repeat (ends = picks).
    pub(crate) fn repeat(self) -> usize {
        match self {
            Weave::Plain => 2,
            Weave::Twill21 => 3,
            Weave::Twill31 | Weave::Basket => 4,
            Weave::Satin5 => 5,
        }
    }

    /// Whether warp end `i` passes over weft pick `j` (indices modulo the repeat).
    pub(crate) fn warp_over(self, i: usize, j: usize) -> bool {
        let n = self.repeat();
        let (i, j) = (i % n, j % n);
        match self {
            Weave::Plain => (i + j) % 2 == 0,
            Weave::Twill21 => (j + n - i) % n < 2,
            Weave::Twill31 => (j + n - i) % n < 3,
            Weave::Satin5 => (j + 2 * n - 2 * i) % n != 0,
            Weave::Basket => (i / 2 + j / 2) % 2 == 0,
        }
    }
}

/// A periodic tile of cells: `width` columns (along the weft, `x`) by `height` rows (along
/// the warp, `y`), row-major, row 0 at the bottom.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Tile {
    width: usize,
    height: usize,
    cells: Vec<Cell>,
}

impl Tile {
    /// A tile from its cells, row-major with row 0 at the bottom.
    pub fn new(width: usize, height: usize, cells: Vec<Cell>) -> Result<Tile, WeaveError> {
        if width == 0 || height == 0 {
            return Err(WeaveError::EmptyTile);
        }
        let expected = width.checked_mul(height).ok_or(WeaveError::CellCount {
            width,
            height,
            expected: usize::MAX,
            got: cells.len(),
        })?;
        if cells.len() != expected {
            return Err(WeaveError::CellCount {
                width,
                height,
                expected,
                got: cells.len(),
            });
        }
        Ok(Tile {
            width,
            height,
            cells,
        })
    }

    /// A tile from a text grid: one line per row, the **top line is the top row**; one
    /// character per cell: `W` warp up, `w` warp down, `F` weft up, `f` weft down, `.` gap.
    /// Spaces and tabs inside a line are ignored (so cells may be spaced out), and blank
    /// lines are skipped. Errors name the line (1-based, from the top of the text) and the
    /// character (1-based).
    ///
    /// ```
    /// # use madder::weave::{Tile, Weave};
    /// let plain = Tile::parse("
    ///     FW
    ///     WF
    /// ").unwrap();
    /// assert_eq!(plain, Tile::builtin(Weave::Plain, false));
    /// ```
    pub fn parse(rows: &str) -> Result<Tile, WeaveError> {
        let mut lines: Vec<Vec<Cell>> = Vec::new();
        let mut width = None;
        for (k, line) in rows.lines().enumerate() {
            let mut row = Vec::new();
            for (c, ch) in line.chars().enumerate() {
                if ch == ' ' || ch == '\t' || ch == '\r' {
                    continue;
                }
                row.push(Cell::from_char(ch).ok_or(WeaveError::UnknownCell {
                    line: k + 1,
                    column: c + 1,
                    ch,
                })?);
            }
            if row.is_empty() {
                continue;
            }
            match width {
                None => width = Some(row.len()),
                Some(w) if w != row.len() => {
                    return Err(WeaveError::RaggedRow {
                        line: k + 1,
                        expected: w,
                        got: row.len(),
                    });
                }
                _ => {}
            }
            lines.push(row);
        }
        let width = width.ok_or(WeaveError::EmptyTile)?;
        let height = lines.len();
        let cells = lines.into_iter().rev().flatten().collect();
        Tile::new(width, height, cells)
    }

    /// A built-in weave, with (`gaps = true`) or without gap cells between the yarns; see
    /// the module documentation for both layouts.
    pub fn builtin(weave: Weave, gaps: bool) -> Tile {
        let n = weave.repeat();
        let crossing = |i: usize, j: usize| {
            if weave.warp_over(i, j) {
                Cell::Warp { up: true }
            } else {
                Cell::Weft { up: true }
            }
        };
        if !gaps {
            let cells = (0..n)
                .flat_map(|j| (0..n).map(move |i| (i, j)))
                .map(|(i, j)| crossing(i, j))
                .collect();
            return Tile {
                width: n,
                height: n,
                cells,
            };
        }
        let m = 2 * n;
        let mut cells = Vec::with_capacity(m * m);
        for y in 0..m {
            for x in 0..m {
                let (i, j) = (x / 2, y / 2);
                cells.push(match (x % 2, y % 2) {
                    (0, 0) => crossing(i, j),
                    // weft j from end i to end i + 1: up if over either of them
                    (1, 0) => Cell::Weft {
                        up: !weave.warp_over(i, j) || !weave.warp_over(i + 1, j),
                    },
                    // warp i from pick j to pick j + 1: up if over either of them
                    (0, 1) => Cell::Warp {
                        up: weave.warp_over(i, j) || weave.warp_over(i, j + 1),
                    },
                    _ => Cell::Gap,
                });
            }
        }
        Tile {
            width: m,
            height: m,
            cells,
        }
    }

    /// Columns of cells (along `x`, the weft).
    pub fn width(&self) -> usize {
        self.width
    }

    /// Rows of cells (along `y`, the warp).
    pub fn height(&self) -> usize {
        self.height
    }

    /// Cells, row-major, row 0 at the bottom.
    pub fn cells(&self) -> &[Cell] {
        &self.cells
    }

    /// The cell at `row` (0 = bottom) and `col` (0 = left), periodically wrapped.
    pub fn cell(&self, row: isize, col: isize) -> Cell {
        let r = row.rem_euclid(self.height as isize) as usize;
        let c = col.rem_euclid(self.width as isize) as usize;
        self.cells[r * self.width + c]
    }
}

/// The text grid of [`Tile::parse`] (top row first), one line per row.
impl fmt::Display for Tile {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for r in (0..self.height).rev() {
            let row = &self.cells[r * self.width..(r + 1) * self.width];
            let line: String = row.iter().map(|c| c.to_char()).collect();
            writeln!(f, "{line}")?;
        }
        Ok(())
    }
}

/// Permeability coefficient `D` per kind of neighbouring cell pair (seed §2.2.1). The
/// default is the seed's table (§2.3): gap–gap 1, weft–weft 100, warp–warp 500,
/// gap–weft 10, gap–warp 50, weft–warp 200.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PairCoefficients {
    /// Two gap cells.
    pub gap_gap: f64,
    /// Two weft cells (see the module table for which layers).
    pub weft_weft: f64,
    /// Two warp cells (see the module table for which layers).
    pub warp_warp: f64,
    /// A gap and a weft cell.
    pub gap_weft: f64,
    /// A gap and a warp cell.
    pub gap_warp: f64,
    /// A weft and a warp cell, or parallel yarns in different layers.
    pub weft_warp: f64,
}

impl Default for PairCoefficients {
    fn default() -> Self {
        PairCoefficients {
            gap_gap: 1.0,
            weft_weft: 100.0,
            warp_warp: 500.0,
            gap_weft: 10.0,
            gap_warp: 50.0,
            weft_warp: 200.0,
        }
    }
}

impl PairCoefficients {
    /// Every coefficient must be finite and `> 0`: a zero would make a cell surrounded by
    /// such pairs impermeable, and its tensor singular.
    pub fn validate(&self) -> Result<(), WeaveError> {
        for (pair, value) in [
            ("gap–gap", self.gap_gap),
            ("weft–weft", self.weft_weft),
            ("warp–warp", self.warp_warp),
            ("gap–weft", self.gap_weft),
            ("gap–warp", self.gap_warp),
            ("weft–warp", self.weft_warp),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(WeaveError::NonPositiveCoefficient { pair, value });
            }
        }
        Ok(())
    }

    /// The name and coefficient of the pair (`a`, `b`) of cells adjacent along `x`
    /// (`along_x`) or along `y`; see the module table.
    pub fn pair_kind(&self, a: Cell, b: Cell, along_x: bool) -> (&'static str, f64) {
        use Cell::*;
        let weft_warp = ("weft–warp", self.weft_warp);
        match (a, b) {
            (Gap, Gap) => ("gap–gap", self.gap_gap),
            (Gap, Warp { .. }) | (Warp { .. }, Gap) => ("gap–warp", self.gap_warp),
            (Gap, Weft { .. }) | (Weft { .. }, Gap) => ("gap–weft", self.gap_weft),
            (Warp { .. }, Weft { .. }) | (Weft { .. }, Warp { .. }) => weft_warp,
            (Warp { up: p }, Warp { up: q }) => {
                if !along_x || p == q {
                    ("warp–warp", self.warp_warp)
                } else {
                    weft_warp
                }
            }
            (Weft { up: p }, Weft { up: q }) => {
                if along_x || p == q {
                    ("weft–weft", self.weft_weft)
                } else {
                    weft_warp
                }
            }
        }
    }
}

/// Per-cell diffusion tensors of a tile (seed §2.2.1): `S = ½[D_left + D_right, 0; 0,
/// D_top + D_bottom]` with neighbours wrapped periodically; row-major, row 0 at the bottom,
/// `[s11, s12, s22]` in the (weft, warp) basis. A coefficient that is not finite and
/// positive is an error naming the first cell (row, column) that borders such a pair;
/// coefficients of pairs the tile does not contain are not used and not checked.
pub fn cell_tensors(tile: &Tile, d: &PairCoefficients) -> Result<Vec<Tensor2>, WeaveError> {
    let mut out = Vec::with_capacity(tile.cells.len());
    for r in 0..tile.height as isize {
        for c in 0..tile.width as isize {
            let me = tile.cell(r, c);
            let [left, right, bottom, top] =
                [(0, -1, true), (0, 1, true), (-1, 0, false), (1, 0, false)]
                    .map(|(dr, dc, along_x)| d.pair_kind(me, tile.cell(r + dr, c + dc), along_x));
            if let Some(&(pair, value)) = [left, right, bottom, top]
                .iter()
                .find(|(_, v)| !(v.is_finite() && *v > 0.0))
            {
                return Err(WeaveError::CellCoefficient {
                    row: r as usize,
                    col: c as usize,
                    pair,
                    value,
                });
            }
            out.push([0.5 * (left.1 + right.1), 0.0, 0.5 * (top.1 + bottom.1)]);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drafts_interlace_once_per_row_and_column_where_they_should() {
        for w in Weave::ALL {
            let n = w.repeat();
            for j in 0..n {
                let over = (0..n).filter(|&i| w.warp_over(i, j)).count();
                let expected = match w {
                    Weave::Plain | Weave::Basket => n / 2,
                    Weave::Twill21 => 2,
                    Weave::Twill31 => 3,
                    Weave::Satin5 => 4,
                };
                assert_eq!(over, expected, "{w:?} pick {j}");
            }
        }
        // satin: no two interlacings touch (move number 2 is coprime to 5 and ≠ ±1)
        for i in 0..5 {
            for j in 0..5 {
                if !Weave::Satin5.warp_over(i, j) {
                    for (di, dj) in [(1, 0), (0, 1), (4, 0), (0, 4)] {
                        assert!(Weave::Satin5.warp_over(i + di, j + dj));
                    }
                }
            }
        }
    }

    #[test]
    fn text_round_trip_and_orientation() {
        let t = Tile::parse("W.\n  f F \n\n").unwrap();
        assert_eq!((t.width(), t.height()), (2, 2));
        // the last line is row 0 (bottom)
        assert_eq!(t.cell(0, 0), Cell::Weft { up: false });
        assert_eq!(t.cell(0, 1), Cell::Weft { up: true });
        assert_eq!(t.cell(1, 0), Cell::Warp { up: true });
        assert_eq!(t.cell(1, 1), Cell::Gap);
        assert_eq!(t.to_string(), "W.\nfF\n");
        for w in Weave::ALL {
            for gaps in [false, true] {
                let b = Tile::builtin(w, gaps);
                assert_eq!(Tile::parse(&b.to_string()).unwrap(), b);
            }
        }
    }

    #[test]
    fn plain_weave_with_gaps_layout() {
        // worked by hand from the draft (i + j) mod 2 = 0: crossings at even (x, y), weft
        // segments at (odd, even), warp segments at (even, odd), gaps at (odd, odd)
        let t = Tile::builtin(Weave::Plain, true);
        assert_eq!(t.to_string(), "W.W.\nFFWF\nW.W.\nWFFF\n");
        let t = Tile::builtin(Weave::Twill21, false);
        assert_eq!(t.to_string(), "FWW\nWWF\nWFW\n");
    }

    #[test]
    fn cell_tensors_by_hand() {
        let d = PairCoefficients::default();
        // top row "W.", bottom row "fF"; every neighbour worked out with periodic wrap
        let t = Tile::parse("W.\nfF").unwrap();
        let s = cell_tensors(&t, &d).unwrap();
        assert_eq!(
            s,
            vec![
                [100.0, 0.0, 200.0], // f: weft yarn left/right, warp crossings above/below
                [100.0, 0.0, 10.0],  // F: weft yarn left/right, gaps above/below
                [50.0, 0.0, 200.0],  // W: gaps left/right, weft crossings above/below
                [50.0, 0.0, 10.0],   // .: warp left/right, weft above/below
            ]
        );
        // neighbouring parallel warps: same layer → warp–warp, different layers → weft–warp;
        // along its own yarn (the 1-row tile wraps onto itself) a warp is always warp–warp
        let same = cell_tensors(&Tile::parse("WW").unwrap(), &d).unwrap();
        let diff = cell_tensors(&Tile::parse("Ww").unwrap(), &d).unwrap();
        assert_eq!(same, vec![[500.0, 0.0, 500.0]; 2]);
        assert_eq!(diff, vec![[200.0, 0.0, 500.0]; 2]);
        // and the same for wefts, transposed
        let diff = cell_tensors(&Tile::parse("F\nf").unwrap(), &d).unwrap();
        assert_eq!(diff, vec![[100.0, 0.0, 200.0]; 2]);
        // a plain weave without gaps touches only warp–weft pairs
        let plain = cell_tensors(&Tile::builtin(Weave::Plain, false), &d).unwrap();
        assert_eq!(plain, vec![[200.0, 0.0, 200.0]; 4]);
    }
}
