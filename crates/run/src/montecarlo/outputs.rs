//! The files a run writes from its trials: `epochs.csv` and `trials.parquet`.

use crate::engine::trial::TrialResult;
use std::io::Write;

/// Which of a run's outputs to write (`run --outputs`): `summary.json` and `run.json` are
/// always written; the rest can be left out to write less (10 000 default-world trials
/// write ≈ 1.5 GB with everything).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OutputSet {
    /// `report.html`.
    pub report: bool,
    /// `epochs.csv`.
    pub epochs: bool,
    /// `trials.parquet`.
    pub parquet: bool,
    /// `trials/trial-NNNNNN.json.gz`, which `--resume` and `merge` need.
    pub trials: bool,
}

impl OutputSet {
    /// Every output.
    pub const ALL: OutputSet = OutputSet {
        report: true,
        epochs: true,
        parquet: true,
        trials: true,
    };

    /// The names `--outputs` takes.
    pub const NAMES: [&'static str; 6] =
        ["summary", "report", "epochs", "parquet", "trials", "all"];

    /// Parses a comma-separated list of [`OutputSet::NAMES`].
    ///
    /// # Errors
    /// A message naming the unknown entry and the names expected.
    pub fn parse(list: &str) -> Result<Self, String> {
        let mut set = OutputSet {
            report: false,
            epochs: false,
            parquet: false,
            trials: false,
        };
        for name in list.split(',').map(str::trim) {
            match name.to_ascii_lowercase().as_str() {
                "summary" => {}
                "report" => set.report = true,
                "epochs" => set.epochs = true,
                "parquet" => set.parquet = true,
                "trials" => set.trials = true,
                "all" => set = OutputSet::ALL,
                _ => {
                    return Err(format!(
                    "--outputs: {name:?} is not an output; expected a comma-separated list of {}",
                    Self::NAMES.join(", ")
                ))
                }
            }
        }
        Ok(set)
    }
}

/// The header of `epochs.csv`.
const EPOCHS_CSV_HEADER: &str = "trial,estimator,t_s,err_3d_m,err_h_m,nees_pos,pos_sigma_m,used,rejected,rejected_gate,mean_nis,gdop,mode,numerical_failure,since_update_s\n";

/// `epochs.csv`, written a trial at a time: every estimator's epochs of every trial (one
/// row per trial, estimator and epoch; empty cells where an estimator had no estimate),
/// for pandas and spreadsheets.
///
/// Columns: `trial, estimator, t_s, err_3d_m, err_h_m, nees_pos, pos_sigma_m, used,
/// rejected, rejected_gate, mean_nis, gdop, mode, numerical_failure, since_update_s`
/// (seconds since the estimator last used a measurement: 0 at an update, positive while it
/// coasts, empty before its first). Every estimator has a row at each of the world's
/// scoring instants, the same for all (see `engine::trial::Scoring`). Trials are pushed in
/// trial order; within one, rows follow the world's estimator order, then time, so the
/// file is identical for any thread count.
pub struct EpochsCsv<W: Write> {
    w: W,
    line: String,
}

impl<W: Write> EpochsCsv<W> {
    /// Writes the header.
    ///
    /// # Errors
    /// I/O errors of `w`.
    pub fn new(mut w: W) -> std::io::Result<Self> {
        w.write_all(EPOCHS_CSV_HEADER.as_bytes())?;
        Ok(Self {
            w,
            line: String::new(),
        })
    }

    /// Writes one trial's rows.
    ///
    /// # Errors
    /// I/O errors of the writer.
    pub fn push(&mut self, r: &TrialResult) -> std::io::Result<()> {
        use std::fmt::Write as _;
        struct Opt(Option<f64>);
        impl std::fmt::Display for Opt {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                match self.0 {
                    Some(x) => write!(f, "{x:.6}"),
                    None => Ok(()),
                }
            }
        }
        for est in &r.estimators {
            // Names are free text: quote them as CSV requires.
            let name = format!("\"{}\"", est.name.replace('"', "\"\""));
            for e in &est.epochs {
                self.line.clear();
                let _ = writeln!(
                    self.line,
                    "{},{},{:.3},{},{},{},{},{},{},{},{},{},{},{},{}",
                    r.trial,
                    name,
                    e.t_s,
                    Opt(e.err_3d_m),
                    Opt(e.err_h_m),
                    Opt(e.nees_pos),
                    Opt(e.pos_sigma_m),
                    e.used,
                    e.rejected,
                    e.rejected_gate,
                    Opt(e.mean_nis),
                    Opt(e.gdop),
                    e.mode.as_deref().unwrap_or(""),
                    u8::from(e.numerical_failure),
                    Opt(e.since_update_s)
                );
                self.w.write_all(self.line.as_bytes())?;
            }
        }
        Ok(())
    }

    /// The writer, flushed.
    ///
    /// # Errors
    /// I/O errors of the flush.
    pub fn finish(mut self) -> std::io::Result<W> {
        self.w.flush()?;
        Ok(self.w)
    }
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
  OPTIONAL DOUBLE since_update_s;
  OPTIONAL BYTE_ARRAY mode (UTF8);
  REQUIRED INT32 n_gps;
  REQUIRED INT32 n_bds;
  REQUIRED INT32 used;
  REQUIRED INT32 rejected;
  REQUIRED INT32 rejected_gate;
  REQUIRED INT32 nis_dof;
  REQUIRED BOOLEAN numerical_failure;
}";

/// Rows per Parquet row group: large enough for fast scans (a few trials of a typical
/// world per group), small enough that the writer's columns stay near 16 MB — the largest
/// buffer a long run holds.
const ROWS_PER_GROUP: usize = 65_536;

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

/// `trials.parquet`, written a trial at a time (see `PARQUET_SCHEMA` for the columns),
/// in the same row order as [`EpochsCsv`]: trial, then the world's estimator order, then
/// time. A row group is written every `ROWS_PER_GROUP` rows, so the writer holds at most
/// one group of columns. The bytes depend only on the trials, so a merged or resumed run
/// writes the same file.
pub struct TrialsParquet<W: Write + Send> {
    writer: parquet::file::writer::SerializedFileWriter<W>,
    frame: crate::core::EnuFrame,
    cols: Vec<Column>,
    rows: usize,
}

fn new_columns() -> Vec<Column> {
    let mut c = vec![Column::I64(Vec::new()), Column::Str(Vec::new())];
    c.extend((0..7).map(|_| Column::F64(Vec::new())));
    c.extend((0..14).map(|_| Column::OptF64(Vec::new(), Vec::new())));
    c.push(Column::OptStr(Vec::new(), Vec::new()));
    c.extend((0..6).map(|_| Column::I32(Vec::new())));
    c.push(Column::Bool(Vec::new()));
    c
}

impl<W: Write + Send> TrialsParquet<W> {
    /// Starts the file in `w`; positions are also given in `frame`'s ENU.
    ///
    /// # Errors
    /// Parquet encoding or I/O errors.
    pub fn new(w: W, frame: &crate::core::EnuFrame) -> parquet::errors::Result<Self> {
        use parquet::file::properties::WriterProperties;
        use std::sync::Arc;
        let schema = Arc::new(parquet::schema::parser::parse_message_type(PARQUET_SCHEMA)?);
        let props = Arc::new(
            // Statistics per column chunk (in the footer, for readers' predicate pushdown)
            // but no page index: the writer keeps every page's index entries until the
            // footer, which made its memory grow with the trials of a long run.
            WriterProperties::builder()
                .set_compression(parquet::basic::Compression::SNAPPY)
                .set_statistics_enabled(parquet::file::properties::EnabledStatistics::Chunk)
                .set_offset_index_disabled(true)
                .set_created_by(format!("hybridnav {}", env!("CARGO_PKG_VERSION")))
                .build(),
        );
        let cols = new_columns();
        debug_assert_eq!(cols.len(), schema.get_fields().len());
        Ok(Self {
            writer: parquet::file::writer::SerializedFileWriter::new(w, schema, props)?,
            frame: frame.clone(),
            cols,
            rows: 0,
        })
    }

    fn flush_group(&mut self) -> parquet::errors::Result<()> {
        let mut rg = self.writer.next_row_group()?;
        let mut k = 0;
        while let Some(mut col) = rg.next_column()? {
            self.cols[k].write(&mut col)?;
            col.close()?;
            k += 1;
        }
        rg.close()?;
        self.cols = new_columns();
        Ok(())
    }

    /// Adds one trial's rows.
    ///
    /// # Errors
    /// Parquet encoding or I/O errors.
    pub fn push(&mut self, r: &TrialResult) -> parquet::errors::Result<()> {
        use nalgebra::Vector3;
        use parquet::data_type::ByteArray;
        for est in &r.estimators {
            let name = ByteArray::from(est.name.as_str());
            for e in &est.epochs {
                let truth = Vector3::from(e.truth_ecef_m);
                let truth_enu = self.frame.enu_of_ecef(&truth);
                let est_ecef = e.est_ecef_m.map(Vector3::from);
                let est_enu = est_ecef.map(|p| self.frame.enu_of_ecef(&p));
                let mut it = self.cols.iter_mut();
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
                    e.since_update_s,
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
                self.rows += 1;
                if self.rows % ROWS_PER_GROUP == 0 {
                    self.flush_group()?;
                }
            }
        }
        Ok(())
    }

    /// Writes the last row group and the footer; returns the writer.
    ///
    /// # Errors
    /// Parquet encoding or I/O errors.
    pub fn finish(mut self) -> parquet::errors::Result<W> {
        if self.rows % ROWS_PER_GROUP != 0 || self.rows == 0 {
            self.flush_group()?;
        }
        self.writer.into_inner()
    }
}
