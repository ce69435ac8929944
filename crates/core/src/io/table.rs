//! A small column table written as CSV or Parquet with the same columns, for the dataset
//! export (one trial's measurements fit in memory; the Monte Carlo outputs, which can be
//! large, stream their own row groups instead).

use parquet::data_type::ByteArray;
use std::fmt::Write;

/// One column's values.
#[derive(Clone, Debug)]
pub enum Values {
    F64(Vec<f64>),
    /// Nullable numbers: `None` is an empty CSV cell and a Parquet null.
    OptF64(Vec<Option<f64>>),
    I64(Vec<i64>),
    Str(Vec<String>),
}

impl Values {
    fn len(&self) -> usize {
        match self {
            Values::F64(v) => v.len(),
            Values::OptF64(v) => v.len(),
            Values::I64(v) => v.len(),
            Values::Str(v) => v.len(),
        }
    }
}

/// Named columns of equal length.
#[derive(Clone, Debug, Default)]
pub struct Table {
    pub columns: Vec<(String, Values)>,
}

/// Formats a float for CSV: the shortest text that parses back to the same value, so a
/// CSV reader recovers exactly what the Parquet file holds.
fn csv_f64(x: f64) -> String {
    if x.is_finite() {
        format!("{x:?}")
    } else {
        String::new()
    }
}

fn csv_str(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

impl Table {
    /// Adds a column.
    pub fn push(&mut self, name: &str, values: Values) {
        self.columns.push((name.to_string(), values));
    }

    /// Rows (the first column's length).
    pub fn rows(&self) -> usize {
        self.columns.first().map_or(0, |(_, v)| v.len())
    }

    fn check(&self) -> Result<(), String> {
        let n = self.rows();
        match self.columns.iter().find(|(_, v)| v.len() != n) {
            Some((name, v)) => Err(format!(
                "column {name} has {} rows where the table has {n}",
                v.len()
            )),
            None => Ok(()),
        }
    }

    /// The table as RFC 4180 CSV with a header line.
    ///
    /// # Errors
    /// Columns of different lengths.
    pub fn to_csv(&self) -> Result<String, String> {
        self.check()?;
        let names: Vec<&str> = self.columns.iter().map(|(n, _)| n.as_str()).collect();
        let mut s = names.join(",");
        s.push('\n');
        for r in 0..self.rows() {
            for (k, (_, v)) in self.columns.iter().enumerate() {
                if k > 0 {
                    s.push(',');
                }
                match v {
                    Values::F64(v) => s.push_str(&csv_f64(v[r])),
                    Values::OptF64(v) => s.push_str(&v[r].map(csv_f64).unwrap_or_default()),
                    Values::I64(v) => {
                        let _ = write!(s, "{}", v[r]);
                    }
                    Values::Str(v) => s.push_str(&csv_str(&v[r])),
                }
            }
            s.push('\n');
        }
        Ok(s)
    }

    /// The table as a Snappy-compressed Parquet file (UTF-8 strings, nullable doubles for
    /// optional columns).
    ///
    /// # Errors
    /// Columns of different lengths, or a Parquet encoding error.
    pub fn to_parquet(&self) -> Result<Vec<u8>, String> {
        use parquet::data_type::{ByteArrayType, DoubleType, Int64Type};
        use parquet::file::properties::WriterProperties;
        use parquet::file::writer::SerializedFileWriter;
        use std::sync::Arc;
        self.check()?;
        let mut schema = String::from("message hybridnav_table {\n");
        for (name, v) in &self.columns {
            let field = match v {
                Values::F64(_) => "REQUIRED DOUBLE",
                Values::OptF64(_) => "OPTIONAL DOUBLE",
                Values::I64(_) => "REQUIRED INT64",
                Values::Str(_) => "REQUIRED BYTE_ARRAY",
            };
            let utf8 = if matches!(v, Values::Str(_)) {
                " (UTF8)"
            } else {
                ""
            };
            let _ = writeln!(schema, "  {field} {name}{utf8};");
        }
        schema.push('}');
        let pq = |e: parquet::errors::ParquetError| e.to_string();
        let schema = Arc::new(parquet::schema::parser::parse_message_type(&schema).map_err(pq)?);
        let props = Arc::new(
            WriterProperties::builder()
                .set_compression(parquet::basic::Compression::SNAPPY)
                .set_created_by(format!("hybridnav {}", env!("CARGO_PKG_VERSION")))
                .build(),
        );
        let mut writer = SerializedFileWriter::new(Vec::new(), schema, props).map_err(pq)?;
        let mut rg = writer.next_row_group().map_err(pq)?;
        let mut k = 0;
        while let Some(mut col) = rg.next_column().map_err(pq)? {
            match &self.columns[k].1 {
                Values::F64(v) => col.typed::<DoubleType>().write_batch(v, None, None),
                Values::OptF64(v) => {
                    let vals: Vec<f64> = v.iter().flatten().copied().collect();
                    let def: Vec<i16> = v.iter().map(|x| i16::from(x.is_some())).collect();
                    col.typed::<DoubleType>()
                        .write_batch(&vals, Some(&def), None)
                }
                Values::I64(v) => col.typed::<Int64Type>().write_batch(v, None, None),
                Values::Str(v) => {
                    let vals: Vec<ByteArray> =
                        v.iter().map(|s| ByteArray::from(s.as_str())).collect();
                    col.typed::<ByteArrayType>().write_batch(&vals, None, None)
                }
            }
            .map_err(pq)?;
            col.close().map_err(pq)?;
            k += 1;
        }
        rg.close().map_err(pq)?;
        writer.into_inner().map_err(pq)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_round_trips_floats_and_quotes_text() {
        let mut t = Table::default();
        t.push("x", Values::F64(vec![0.1 + 0.2, -1e-300]));
        t.push("y", Values::OptF64(vec![None, Some(2.5)]));
        t.push("name", Values::Str(vec!["a,b".into(), "q\"".into()]));
        let csv = t.to_csv().unwrap();
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines[0], "x,y,name");
        assert_eq!(lines[1], "0.30000000000000004,,\"a,b\"");
        assert_eq!(lines[2], "-1e-300,2.5,\"q\"\"\"");
        let x: f64 = lines[1].split(',').next().unwrap().parse().unwrap();
        assert_eq!(x, 0.1 + 0.2);
    }

    #[test]
    fn ragged_columns_are_refused() {
        let mut t = Table::default();
        t.push("a", Values::I64(vec![1, 2]));
        t.push("b", Values::I64(vec![1]));
        assert!(t.to_csv().unwrap_err().contains("column b has 1 rows"));
        assert!(t.to_parquet().is_err());
    }

    #[test]
    fn parquet_reads_back_with_nulls() {
        use parquet::file::reader::{FileReader, SerializedFileReader};
        let mut t = Table::default();
        t.push("a", Values::I64(vec![1, 2, 3]));
        t.push("b", Values::OptF64(vec![Some(1.5), None, Some(-2.0)]));
        t.push(
            "s",
            Values::Str(vec!["G05".into(), "C01".into(), "x".into()]),
        );
        let bytes = t.to_parquet().unwrap();
        let path =
            std::env::temp_dir().join(format!("hybridnav-table-{}.parquet", std::process::id()));
        std::fs::write(&path, bytes).unwrap();
        let r = SerializedFileReader::new(std::fs::File::open(&path).unwrap()).unwrap();
        assert_eq!(r.metadata().file_metadata().num_rows(), 3);
        let rows: Vec<String> = r
            .get_row_iter(None)
            .unwrap()
            .map(|row| row.unwrap().to_string())
            .collect();
        assert_eq!(rows[1], "{a: 2, b: null, s: \"C01\"}");
        assert_eq!(rows[2], "{a: 3, b: -2E0, s: \"x\"}");
        let _ = std::fs::remove_file(&path);
    }
}
