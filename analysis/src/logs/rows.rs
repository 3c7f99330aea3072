//! Rows of equal width stored in one flat vector: the per-step inputs of a
//! run ([`Inputs`]), the Jacobian rows of a fit's residuals. A long log has
//! millions of steps, and a `Vec` per row would cost an allocation (and its
//! bookkeeping, more than the values) each. The values are a [`Column`], so a
//! slice shares them.
use crate::logs::column::Column;
use std::ops::Index;

/// Per-step model inputs of a run, in the spec's order.
pub type Inputs = Rows;

#[derive(Debug, Clone, Default, PartialEq)]
pub struct Rows {
    /// Values per row.
    width: usize,
    steps: usize,
    values: Column<f64>,
}

impl Rows {
    /// No rows yet, `width` values each.
    pub fn new(width: usize) -> Rows {
        Rows {
            width,
            steps: 0,
            values: Column::default(),
        }
    }

    /// `steps` rows of `width` values, row-major.
    pub fn from_flat(steps: usize, width: usize, values: Vec<f64>) -> Rows {
        assert_eq!(steps * width, values.len(), "{steps} x {width} rows");
        Rows {
            width,
            steps,
            values: values.into(),
        }
    }

    pub fn len(&self) -> usize {
        self.steps
    }

    pub fn is_empty(&self) -> bool {
        self.steps == 0
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn first(&self) -> Option<&[f64]> {
        (self.steps > 0).then(|| &self[0])
    }

    pub fn iter(&self) -> impl Iterator<Item = &[f64]> + '_ {
        (0..self.steps).map(move |k| &self[k])
    }

    /// Append a row of `width` values.
    pub fn push(&mut self, row: impl IntoIterator<Item = f64>) {
        let before = self.values.len();
        self.values.extend(row);
        assert_eq!(self.values.len() - before, self.width, "row width");
        self.steps += 1;
    }

    /// Rows `a..b`, sharing the values.
    pub fn slice(&self, a: usize, b: usize) -> Rows {
        Rows {
            width: self.width,
            steps: b - a,
            values: self.values.slice(a * self.width, b * self.width),
        }
    }
}

impl Index<usize> for Rows {
    type Output = [f64];
    fn index(&self, k: usize) -> &[f64] {
        assert!(k < self.steps, "step {k} of {}", self.steps);
        &self.values[k * self.width..(k + 1) * self.width]
    }
}

/// Rows of equal width (tests and benches build inputs this way).
impl<R: AsRef<[f64]>> FromIterator<R> for Rows {
    fn from_iter<I: IntoIterator<Item = R>>(rows: I) -> Rows {
        let (mut width, mut steps, mut values) = (None, 0, Vec::new());
        for r in rows {
            let r = r.as_ref();
            assert_eq!(*width.get_or_insert(r.len()), r.len(), "ragged input rows");
            values.extend_from_slice(r);
            steps += 1;
        }
        Rows {
            width: width.unwrap_or(0),
            steps,
            values: values.into(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_round_trip_and_slice() {
        let u: Rows = [[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]].into_iter().collect();
        assert_eq!((u.len(), u.width()), (3, 2));
        assert_eq!(&u[1], &[3.0, 4.0]);
        assert_eq!(u.first(), Some(&[1.0, 2.0][..]));
        let s = u.slice(1, 3);
        assert_eq!(
            s.iter().collect::<Vec<_>>(),
            vec![&[3.0, 4.0][..], &[5.0, 6.0]]
        );
        let empty: Rows = Vec::<Vec<f64>>::new().into_iter().collect();
        assert!(empty.is_empty() && empty.first().is_none());
    }
}
