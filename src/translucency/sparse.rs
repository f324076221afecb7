//! The sparse matrices of the transport (`K`, `F`, the far-field clusters), in compressed rows
//! as the GPU iteration reads them.

use std::ops::{AddAssign, Mul};

/// A sparse matrix in compressed rows, laid out as the GPU reads it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SparseMatrix<T> {
    /// Row `i`'s entries are `row_offsets[i]..row_offsets[i + 1]`; `rows + 1` offsets.
    pub row_offsets: Vec<u32>,
    /// Column of each entry.
    pub columns: Vec<u32>,
    /// Value of each entry.
    pub values: Vec<T>,
}

impl<T: Copy> SparseMatrix<T> {
    /// Builds the matrix from each row's `(column, value)` entries.
    pub fn from_rows(rows: Vec<Vec<(u32, T)>>) -> Self {
        let mut m = Self {
            row_offsets: Vec::with_capacity(rows.len() + 1),
            columns: Vec::new(),
            values: Vec::new(),
        };
        m.row_offsets.push(0);
        for mut row in rows {
            row.sort_by_key(|e| e.0);
            for (c, v) in row {
                m.columns.push(c);
                m.values.push(v);
            }
            m.row_offsets.push(m.columns.len() as u32);
        }
        m
    }

    /// Number of rows.
    pub fn rows(&self) -> usize {
        self.row_offsets.len().saturating_sub(1)
    }

    /// Number of stored entries.
    pub fn entries(&self) -> usize {
        self.columns.len()
    }

    /// Row `i`'s `(column, value)` entries.
    pub fn row(&self, i: usize) -> impl Iterator<Item = (usize, T)> + '_ {
        let range = self.row_offsets[i] as usize..self.row_offsets[i + 1] as usize;
        self.columns[range.clone()]
            .iter()
            .zip(&self.values[range])
            .map(|(&c, &v)| (c as usize, v))
    }

    /// The value at `(i, j)`, zero where nothing is stored.
    pub fn get(&self, i: usize, j: usize) -> Option<T> {
        self.row(i).find(|&(c, _)| c == j).map(|(_, v)| v)
    }

    /// `Σ_i w_i M_ij` for each of `columns` columns: the column sums with each row weighted
    /// (by its patch's area: the flux a column's unit exitance gives off in all).
    pub fn weighted_column_sums(&self, row_weights: &[f32], columns: usize) -> Vec<T>
    where
        T: Mul<f32, Output = T> + Default + AddAssign,
    {
        let mut sums = vec![T::default(); columns];
        for (i, &w) in row_weights.iter().enumerate().take(self.rows()) {
            for (j, v) in self.row(i) {
                sums[j] += v * w;
            }
        }
        sums
    }

    /// `y = M x`.
    pub fn mul_vec<V>(&self, x: &[V]) -> Vec<V>
    where
        T: Mul<V, Output = V>,
        V: Copy + Default + AddAssign,
    {
        (0..self.rows())
            .map(|i| {
                let mut sum = V::default();
                for (j, v) in self.row(i) {
                    sum += v * x[j];
                }
                sum
            })
            .collect()
    }
}
