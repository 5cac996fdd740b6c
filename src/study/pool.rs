//! Independent captures of one run pooled into one study row: the mean of each statistic over
//! the captures and its 95 % Student-t interval — the spread a lab would see by repeating the
//! experiment (new noise each time; with new layouts, a new print too), which the block bootstrap
//! of a single capture (`dic::bootstrap`) can only estimate from within one image pair.
//!
//! The % increases are paired per capture (each capture's reduced schemes share its frames), so
//! a row's increase is the mean of the per-capture increases and its interval the t interval of
//! that mean (a paired t analysis, e.g. Montgomery & Runger, *Applied Statistics and Probability
//! for Engineers*, § 10-4).

use super::card::CardStats;
use super::rows::{Increase, IncreaseInterval, StudyRow};
use crate::dataset::Manifest;
use crate::dic::{Stats, Summary};
use crate::stats::mean_interval;
use std::collections::HashMap;

/// The study's rows with the captures of every repeated run pooled (runs whose manifest entry
/// names `repeat_of`), in the order of first appearance; rows of other runs pass unchanged.
pub fn pool_captures(manifest: &Manifest, rows: &[StudyRow]) -> Vec<StudyRow> {
    let repeat_of: HashMap<&str, &str> = manifest
        .runs
        .iter()
        .filter_map(|r| Some((r.id.as_str(), r.repeat_of.as_deref()?)))
        .collect();
    // One slot per output row: a row passed through (no pooled id), or the captures of one
    // (pooled run, scheme), at the place of its first capture.
    let mut slots: Vec<(Option<&str>, Vec<&StudyRow>)> = Vec::new();
    let mut slot_of: HashMap<(&str, &str), usize> = HashMap::new();
    for row in rows {
        match repeat_of.get(row.run.as_str()) {
            None => slots.push((None, vec![row])),
            Some(&id) => {
                let k = *slot_of.entry((id, row.scheme.as_str())).or_insert_with(|| {
                    slots.push((Some(id), Vec::new()));
                    slots.len() - 1
                });
                slots[k].1.push(row);
            }
        }
    }
    slots
        .into_iter()
        .map(|(id, members)| match id {
            None => members[0].clone(),
            Some(id) => pool(id, &members),
        })
        .collect()
}

fn pool(id: &str, members: &[&StudyRow]) -> StudyRow {
    let first = members[0];
    let stats = |f: fn(&Summary) -> &Stats| {
        pooled_stats(&members.iter().map(|r| f(&r.summary)).collect::<Vec<_>>())
    };
    // A card's corrected field, pooled as the raw one is (every capture was given the card).
    let card = members
        .iter()
        .map(|r| r.card.as_ref())
        .collect::<Option<Vec<_>>>()
        .map(|cards| CardStats {
            model: cards[0].model.clone(),
            u: pooled_stats(&cards.iter().map(|c| &c.u).collect::<Vec<_>>()),
            v: pooled_stats(&cards.iter().map(|c| &c.v).collect::<Vec<_>>()),
        });
    let increases: Option<Vec<Increase>> = members.iter().map(|r| r.increase_pct).collect();
    let (increase_pct, increase_ci95) = match increases {
        None => (None, None),
        Some(inc) => {
            let field =
                |f: fn(&Increase) -> f64| mean_interval(&inc.iter().map(f).collect::<Vec<_>>());
            let (u, v, exx, eyy, exy) = (
                field(|i| i.u),
                field(|i| i.v),
                field(|i| i.exx),
                field(|i| i.eyy),
                field(|i| i.exy),
            );
            (
                Some(Increase {
                    u: u.0,
                    v: v.0,
                    exx: exx.0,
                    eyy: eyy.0,
                    exy: exy.0,
                }),
                Some(IncreaseInterval {
                    u: u.1,
                    v: v.1,
                    exx: exx.1,
                    eyy: eyy.1,
                    exy: exy.1,
                }),
            )
        }
    };
    StudyRow {
        run: id.to_string(),
        pattern: first.pattern.clone(),
        scheme: first.scheme.clone(),
        fill_factor: first.fill_factor,
        summary: Summary {
            points: members.iter().map(|r| r.summary.points).sum(),
            valid: members.iter().map(|r| r.summary.valid).sum(),
            u: stats(|s| &s.u),
            v: stats(|s| &s.v),
            exx: stats(|s| &s.exx),
            eyy: stats(|s| &s.eyy),
            exy: stats(|s| &s.exy),
        },
        increase_pct,
        increase_ci95,
        expected_px: first.expected_px,
        repeats: members.len(),
        card,
    }
}

/// The statistics of captures pooled: the mean of the means, and of the stds with their t
/// interval.
fn pooled_stats(all: &[&Stats]) -> Stats {
    let (std, std_ci95) = mean_interval(&all.iter().map(|s| s.std).collect::<Vec<_>>());
    Stats {
        mean: mean_interval(&all.iter().map(|s| s.mean).collect::<Vec<_>>()).0,
        std,
        std_ci95,
        min: all.iter().map(|s| s.min).fold(f64::INFINITY, f64::min),
        max: all.iter().map(|s| s.max).fold(f64::NEG_INFINITY, f64::max),
        count: all.iter().map(|s| s.count).sum(),
    }
}
