//! The files a run writes from its trials: `epochs.csv` and `trials.parquet`.

use crate::engine::trial::TrialResult;

/// Every estimator's epochs of every trial as CSV (one row per trial, estimator and epoch;
/// empty cells where an estimator had no estimate), for pandas and spreadsheets.
///
/// Columns: `trial, estimator, t_s, err_3d_m, err_h_m, nees_pos, pos_sigma_m, used,
/// rejected, rejected_gate, mean_nis, gdop, mode, numerical_failure`. Rows are in trial order, then the world's estimator order, then
/// time, so the file is identical for any thread count.
pub fn epochs_csv(results: &[TrialResult]) -> String {
    use std::fmt::Write;
    let mut s = String::from(
        "trial,estimator,t_s,err_3d_m,err_h_m,nees_pos,pos_sigma_m,used,rejected,rejected_gate,mean_nis,gdop,mode,numerical_failure\n",
    );
    let opt = |v: Option<f64>| v.map(|x| format!("{x:.6}")).unwrap_or_default();
    let mut sorted: Vec<&TrialResult> = results.iter().collect();
    sorted.sort_by_key(|r| r.trial);
    for r in sorted {
        for est in &r.estimators {
            // Names are free text: quote them as CSV requires.
            let name = format!("\"{}\"", est.name.replace('"', "\"\""));
            for e in &est.epochs {
                let _ = writeln!(
                    s,
                    "{},{},{:.3},{},{},{},{},{},{},{},{},{},{},{}",
                    r.trial,
                    name,
                    e.t_s,
                    opt(e.err_3d_m),
                    opt(e.err_h_m),
                    opt(e.nees_pos),
                    opt(e.pos_sigma_m),
                    e.used,
                    e.rejected,
                    e.rejected_gate,
                    opt(e.mean_nis),
                    opt(e.gdop),
                    e.mode.as_deref().unwrap_or(""),
                    u8::from(e.numerical_failure)
                );
            }
        }
    }
    s
}

/// The columns of `trials.parquet`, in file order, as a Parquet message type.
///
/// One row per trial, estimator and scored epoch; optional columns are null where the
/// estimator had no estimate (or no NEES, NIS, GDOP or mode that epoch). Positions are
/// given both in ECEF and in the world's ENU frame (its `[world] origin`).
const PARQUET_SCHEMA: &str = "message hybridnav_epochs {
  REQUIRED INT64 trial;
  REQUIRED BYTE_ARRAY estimator (UTF8);
  REQUIRED DOUBLE t_s;
  REQUIRED DOUBLE truth_x_ecef_m;
  REQUIRED DOUBLE truth_y_ecef_m;
  REQUIRED DOUBLE truth_z_ecef_m;
  REQUIRED DOUBLE truth_e_m;
  REQUIRED DOUBLE truth_n_m;
  REQUIRED DOUBLE truth_u_m;
  OPTIONAL DOUBLE est_x_ecef_m;
  OPTIONAL DOUBLE est_y_ecef_m;
  OPTIONAL DOUBLE est_z_ecef_m;
  OPTIONAL DOUBLE est_e_m;
  OPTIONAL DOUBLE est_n_m;
  OPTIONAL DOUBLE est_u_m;
  OPTIONAL DOUBLE err_3d_m;
  OPTIONAL DOUBLE err_h_m;
  OPTIONAL DOUBLE nees_pos;
  OPTIONAL DOUBLE pos_sigma_m;
  OPTIONAL DOUBLE mean_nis;
  OPTIONAL DOUBLE nis;
  OPTIONAL DOUBLE gdop;
  OPTIONAL BYTE_ARRAY mode (UTF8);
  REQUIRED INT32 n_gps;
  REQUIRED INT32 n_bds;
  REQUIRED INT32 used;
  REQUIRED INT32 rejected;
  REQUIRED INT32 rejected_gate;
  REQUIRED INT32 nis_dof;
  REQUIRED BOOLEAN numerical_failure;
}";

/// Rows per Parquet row group: large enough for fast scans, small enough that a writer
/// of a long run never holds more than a few tens of megabytes of columns.
const ROWS_PER_GROUP: usize = 262_144;

/// One column's values for a row group (`def` holds the definition levels of optional
/// columns: 1 present, 0 null).
enum Column {
    I64(Vec<i64>),
    I32(Vec<i32>),
    F64(Vec<f64>),
    OptF64(Vec<f64>, Vec<i16>),
    Str(Vec<parquet::data_type::ByteArray>),
    OptStr(Vec<parquet::data_type::ByteArray>, Vec<i16>),
    Bool(Vec<bool>),
}

impl Column {
    fn push_opt(&mut self, v: Option<f64>) {
        if let Column::OptF64(vals, def) = self {
            match v {
                Some(x) => {
                    vals.push(x);
                    def.push(1);
                }
                None => def.push(0),
            }
        }
    }

    fn write(
        &self,
        w: &mut parquet::file::writer::SerializedColumnWriter<'_>,
    ) -> parquet::errors::Result<()> {
        use parquet::data_type::{BoolType, ByteArrayType, DoubleType, Int32Type, Int64Type};
        match self {
            Column::I64(v) => w.typed::<Int64Type>().write_batch(v, None, None),
            Column::I32(v) => w.typed::<Int32Type>().write_batch(v, None, None),
            Column::F64(v) => w.typed::<DoubleType>().write_batch(v, None, None),
            Column::OptF64(v, d) => w.typed::<DoubleType>().write_batch(v, Some(d), None),
            Column::Str(v) => w.typed::<ByteArrayType>().write_batch(v, None, None),
            Column::OptStr(v, d) => w.typed::<ByteArrayType>().write_batch(v, Some(d), None),
            Column::Bool(v) => w.typed::<BoolType>().write_batch(v, None, None),
        }
        .map(|_| ())
    }
}

/// Every estimator's epochs of every trial as a Parquet file (see [`PARQUET_SCHEMA`] for
/// the columns), in the same row order as [`epochs_csv`]: trial, then the world's
/// estimator order, then time. The bytes depend only on the trials, so a merged or resumed
/// run writes the same file.
///
/// # Errors
/// Parquet encoding errors (none are expected for well-formed records).
pub fn trials_parquet(
    frame: &crate::core::EnuFrame,
    results: &[TrialResult],
) -> Result<Vec<u8>, parquet::errors::ParquetError> {
    use nalgebra::Vector3;
    use parquet::data_type::ByteArray;
    use parquet::file::properties::WriterProperties;
    use parquet::file::writer::SerializedFileWriter;
    use std::sync::Arc;

    let schema = Arc::new(parquet::schema::parser::parse_message_type(PARQUET_SCHEMA)?);
    let props = Arc::new(
        WriterProperties::builder()
            .set_compression(parquet::basic::Compression::SNAPPY)
            .set_created_by(format!("hybridnav {}", env!("CARGO_PKG_VERSION")))
            .build(),
    );
    let mut writer = SerializedFileWriter::new(Vec::new(), schema.clone(), props)?;
    let n_cols = schema.get_fields().len();

    let mut sorted: Vec<&TrialResult> = results.iter().collect();
    sorted.sort_by_key(|r| r.trial);
    let new_columns = || -> Vec<Column> {
        let mut c = vec![Column::I64(Vec::new()), Column::Str(Vec::new())];
        c.extend((0..7).map(|_| Column::F64(Vec::new())));
        c.extend((0..13).map(|_| Column::OptF64(Vec::new(), Vec::new())));
        c.push(Column::OptStr(Vec::new(), Vec::new()));
        c.extend((0..6).map(|_| Column::I32(Vec::new())));
        c.push(Column::Bool(Vec::new()));
        c
    };
    let mut cols = new_columns();
    debug_assert_eq!(cols.len(), n_cols);
    let mut rows = 0usize;
    let flush = |cols: &mut Vec<Column>,
                 writer: &mut SerializedFileWriter<Vec<u8>>|
     -> parquet::errors::Result<()> {
        let mut rg = writer.next_row_group()?;
        let mut k = 0;
        while let Some(mut col) = rg.next_column()? {
            cols[k].write(&mut col)?;
            col.close()?;
            k += 1;
        }
        rg.close()?;
        *cols = new_columns();
        Ok(())
    };
    for r in sorted {
        for est in &r.estimators {
            let name = ByteArray::from(est.name.as_str());
            for e in &est.epochs {
                let truth = Vector3::from(e.truth_ecef_m);
                let truth_enu = frame.enu_of_ecef(&truth);
                let est_ecef = e.est_ecef_m.map(Vector3::from);
                let est_enu = est_ecef.map(|p| frame.enu_of_ecef(&p));
                let mut it = cols.iter_mut();
                let mut next = || it.next().expect("the column list matches the schema");
                if let Column::I64(v) = next() {
                    v.push(r.trial as i64);
                }
                if let Column::Str(v) = next() {
                    v.push(name.clone());
                }
                for x in [
                    e.t_s,
                    truth.x,
                    truth.y,
                    truth.z,
                    truth_enu.x,
                    truth_enu.y,
                    truth_enu.z,
                ] {
                    if let Column::F64(v) = next() {
                        v.push(x);
                    }
                }
                for x in [
                    est_ecef.map(|p| p.x),
                    est_ecef.map(|p| p.y),
                    est_ecef.map(|p| p.z),
                    est_enu.map(|p| p.x),
                    est_enu.map(|p| p.y),
                    est_enu.map(|p| p.z),
                    e.err_3d_m,
                    e.err_h_m,
                    e.nees_pos,
                    e.pos_sigma_m,
                    e.mean_nis,
                    e.nis,
                    e.gdop,
                ] {
                    next().push_opt(x);
                }
                if let Column::OptStr(v, d) = next() {
                    match e.mode.as_deref() {
                        Some(m) => {
                            v.push(ByteArray::from(m));
                            d.push(1);
                        }
                        None => d.push(0),
                    }
                }
                for x in [
                    e.n_gps,
                    e.n_bds,
                    e.used,
                    e.rejected,
                    e.rejected_gate,
                    e.nis_dof,
                ] {
                    if let Column::I32(v) = next() {
                        v.push(i32::try_from(x).unwrap_or(i32::MAX));
                    }
                }
                if let Column::Bool(v) = next() {
                    v.push(e.numerical_failure);
                }
                rows += 1;
                if rows % ROWS_PER_GROUP == 0 {
                    flush(&mut cols, &mut writer)?;
                }
            }
        }
    }
    if rows % ROWS_PER_GROUP != 0 || rows == 0 {
        flush(&mut cols, &mut writer)?;
    }
    writer.into_inner()
}
