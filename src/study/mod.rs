//! The fill-factor study (Hijazi, Rawashdeh & Kähler): a dataset's pairs reduced by every scheme
//! and correlated (`analyze.rs`), its rows (`rows.rs`), independent captures pooled with t
//! intervals (`pool.rs`), a camera card's correction of the rows (`card.rs`) and the paper's findings tested on them (`findings.rs`). Its views
//! (tables, CSV, figures, the findings' table, the files a job writes) are in `report/`.

mod analyze;
mod card;
mod findings;
mod pool;
mod rows;

pub use analyze::{analyze_dataset, analyze_dataset_with, ResultHook, StudyError};
pub use card::{CardCorrection, CardStats};
pub use findings::{paper_findings, Finding, Verdict};
pub use pool::pool_captures;
pub use rows::{Increase, IncreaseInterval, StudyRow};
