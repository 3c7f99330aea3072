//! Per-step model inputs of a run, one row per step, stored in one flat
//! vector: a long log has millions of steps, and a `Vec` per step would cost
//! an allocation (and its bookkeeping, more than the values) each.
use std::ops::Index;

#[derive(Debug, Clone, Default, PartialEq)]
pub struct Inputs {
    /// Values per step (the model's inputs, in the spec's order).
    width: usize,
    steps: usize,
    values: Vec<f64>,
}

impl Inputs {
    /// `steps` rows of `width` values, row-major.
    pub fn from_flat(steps: usize, width: usize, values: Vec<f64>) -> Inputs {
        assert_eq!(steps * width, values.len(), "{steps} x {width} inputs");
        Inputs {
            width,
            steps,
            values,
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

    /// Steps `a..b` as inputs of their own.
    pub fn slice(&self, a: usize, b: usize) -> Inputs {
        Inputs {
            width: self.width,
            steps: b - a,
            values: self.values[a * self.width..b * self.width].to_vec(),
        }
    }
}

impl Index<usize> for Inputs {
    type Output = [f64];
    fn index(&self, k: usize) -> &[f64] {
        assert!(k < self.steps, "step {k} of {}", self.steps);
        &self.values[k * self.width..(k + 1) * self.width]
    }
}

/// Rows of equal width (tests and benches build inputs this way).
impl<R: AsRef<[f64]>> FromIterator<R> for Inputs {
    fn from_iter<I: IntoIterator<Item = R>>(rows: I) -> Inputs {
        let (mut width, mut steps, mut values) = (None, 0, Vec::new());
        for r in rows {
            let r = r.as_ref();
            assert_eq!(*width.get_or_insert(r.len()), r.len(), "ragged input rows");
            values.extend_from_slice(r);
            steps += 1;
        }
        Inputs {
            width: width.unwrap_or(0),
            steps,
            values,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_round_trip_and_slice() {
        let u: Inputs = [[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]].into_iter().collect();
        assert_eq!((u.len(), u.width()), (3, 2));
        assert_eq!(&u[1], &[3.0, 4.0]);
        assert_eq!(u.first(), Some(&[1.0, 2.0][..]));
        let s = u.slice(1, 3);
        assert_eq!(
            s.iter().collect::<Vec<_>>(),
            vec![&[3.0, 4.0][..], &[5.0, 6.0]]
        );
        let empty: Inputs = Vec::<Vec<f64>>::new().into_iter().collect();
        assert!(empty.is_empty() && empty.first().is_none());
    }
}
