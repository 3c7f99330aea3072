//! A run's per-row values, shared between the run and the pieces cut from it.
//!
//! A fit cuts a long log into re-anchored segments, then into windows for the
//! sandwich covariance and pieces for the continuation; diagnosis splits it
//! into training and held-out parts. With owned vectors each cut copied the
//! log (a million-row log is ~80 MB of columns, copied three or four times).
//! A [`Column`] is a range of one reference-counted vector: a cut is a new
//! range, so memory stays the log's own whatever the cuts. Hand-written (40
//! lines) rather than a crate: `bytes::Bytes` is the same idea for `u8` only,
//! and the general crates (e.g. `arc-slice`) are young and little used.
use std::fmt;
use std::ops::{Deref, Range};
use std::sync::Arc;

#[derive(Clone)]
pub struct Column<T> {
    values: Arc<Vec<T>>,
    range: Range<usize>,
}

impl<T> Column<T> {
    /// Rows `a..b` of this column, sharing its values.
    pub fn slice(&self, a: usize, b: usize) -> Column<T> {
        assert!(a <= b && b <= self.len(), "rows {a}..{b} of {}", self.len());
        let start = self.range.start;
        Column {
            values: Arc::clone(&self.values),
            range: start + a..start + b,
        }
    }
}

impl<T: Clone> Column<T> {
    /// Append values: in place while this column is the whole of a vector no
    /// other column shares, else after copying its own rows out.
    pub fn extend(&mut self, values: impl IntoIterator<Item = T>) {
        let whole = self.range.end == self.values.len();
        if !whole || Arc::get_mut(&mut self.values).is_none() {
            *self = self.to_vec().into();
        }
        let v = Arc::get_mut(&mut self.values).expect("a column of its own");
        v.extend(values);
        self.range.end = v.len();
    }
}

impl<T> Deref for Column<T> {
    type Target = [T];
    fn deref(&self) -> &[T] {
        &self.values[self.range.clone()]
    }
}

impl<T> From<Vec<T>> for Column<T> {
    fn from(values: Vec<T>) -> Column<T> {
        let range = 0..values.len();
        Column {
            values: Arc::new(values),
            range,
        }
    }
}

impl<T> FromIterator<T> for Column<T> {
    fn from_iter<I: IntoIterator<Item = T>>(iter: I) -> Column<T> {
        Vec::from_iter(iter).into()
    }
}

impl<'a, T> IntoIterator for &'a Column<T> {
    type Item = &'a T;
    type IntoIter = std::slice::Iter<'a, T>;
    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

impl<T> Default for Column<T> {
    fn default() -> Column<T> {
        Vec::new().into()
    }
}

impl<T: fmt::Debug> fmt::Debug for Column<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_list().entries(self.iter()).finish()
    }
}

impl<T: PartialEq> PartialEq for Column<T> {
    fn eq(&self, other: &Column<T>) -> bool {
        **self == **other
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_slice_shares_its_values_and_extending_never_changes_another_column() {
        let mut whole: Column<f64> = vec![1.0, 2.0, 3.0, 4.0].into();
        let mut piece = whole.slice(1, 3);
        assert_eq!(&*piece, &[2.0, 3.0]);
        assert!(Arc::ptr_eq(&whole.values, &piece.values));
        assert_eq!(&*piece.slice(1, 2), &[3.0]);
        piece.extend([9.0]);
        assert_eq!(
            (&*piece, &*whole),
            (&[2.0, 3.0, 9.0][..], &[1.0, 2.0, 3.0, 4.0][..])
        );
        whole.extend([5.0]);
        assert_eq!(&*whole, &[1.0, 2.0, 3.0, 4.0, 5.0]);
        let mut own: Column<f64> = Column::default();
        own.extend([1.0]);
        own.extend([2.0]);
        assert_eq!(&*own, &[1.0, 2.0]);
    }
}
