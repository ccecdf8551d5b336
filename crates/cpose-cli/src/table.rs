//! `cpose table RUN_DIR...`: the numbers of several runs' `metrics.json` side by side, as one
//! Markdown table (a sweep's summary).
//!
//! Every numeric leaf of a `metrics.json` is a cell: its last key names the column, the keys
//! before it (with the run folder's name in front) name the row; the strings and booleans beside
//! numbers (`fit_stop`, `fit_converged`) are cells too. A `null` leaf (a metric that was not
//! computed) is an empty cell. A JSON integer (a count such as `frames: 500`) prints as
//! an integer; other numbers with four significant digits. So the NeRF task's
//! `{"synthetic": {"posenet": {"rot_err_deg": 0.3}}}` in `runs/rm60` is the cell
//! (`rm60 synthetic/posenet`, `rot_err_deg`).

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;

use anyhow::{Context, bail};
use cpose_core::study::format_value;
use serde_json::Value;

/// One row: its name and its cells by column (numbers, strings, booleans or `null`).
type Row = (String, BTreeMap<String, Value>);

/// The Markdown table of the runs in `dirs`, restricted to `columns` (in that order) when not
/// empty, else all columns sorted by name.
pub fn metrics_table(dirs: &[PathBuf], columns: &[String]) -> anyhow::Result<String> {
    let mut rows: Vec<Row> = Vec::new();
    for dir in dirs {
        let path = dir.join("metrics.json");
        let text = std::fs::read_to_string(&path).with_context(|| {
            format!(
                "cannot read {} (a run folder holds one when its run finished)",
                path.display()
            )
        })?;
        let value: Value = serde_json::from_str(&text)
            .with_context(|| format!("{} is not valid JSON", path.display()))?;
        let run = dir
            .file_name()
            .map_or_else(|| dir.display().to_string(), |n| n.to_string_lossy().into());
        let before = rows.len();
        collect_rows(&value, &run, "", &mut rows);
        if rows.len() == before {
            bail!(
                "{} holds no metrics: expected a JSON object with numbers at some level, \
                 such as {{\"rot_err_deg\": 0.3}}",
                path.display()
            );
        }
    }
    let all: BTreeSet<&String> = rows.iter().flat_map(|(_, cells)| cells.keys()).collect();
    if let Some(c) = columns.iter().find(|c| !all.contains(c)) {
        let known: Vec<&str> = all.iter().map(|k| k.as_str()).collect();
        bail!(
            "no run has the metric {c:?} (metrics: {})",
            known.join(", ")
        );
    }
    let names: Vec<String> = if columns.is_empty() {
        all.into_iter().cloned().collect()
    } else {
        columns.to_vec()
    };
    rows.retain(|(_, cells)| names.iter().any(|n| cells.contains_key(n)));
    let mut out = format!("| run | {} |\n|---|", names.join(" | "));
    out.push_str(&"---|".repeat(names.len()));
    out.push('\n');
    for (name, cells) in &rows {
        out.push_str(&format!("| {name} |"));
        for n in &names {
            match cells.get(n) {
                Some(v) if !v.is_null() => out.push_str(&format!(" {} |", format_value(v))),
                _ => out.push_str(" |"),
            }
        }
        out.push('\n');
    }
    Ok(out)
}

/// Appends the rows of `value`, an object at key path `path` of run `run`: one row per object
/// with numeric leaves, which are its cells.
fn collect_rows(value: &Value, run: &str, path: &str, rows: &mut Vec<Row>) {
    let Value::Object(map) = value else {
        return;
    };
    let cells: BTreeMap<String, Value> = map
        .iter()
        .filter(|(_, v)| !(v.is_object() || v.is_array()))
        .map(|(k, v)| (k.clone(), v.clone()))
        .collect();
    if map.values().any(Value::is_number) {
        let name = if path.is_empty() {
            run.to_owned()
        } else {
            format!("{run} {path}")
        };
        rows.push((name, cells));
    }
    for (k, v) in map {
        if v.is_object() {
            let path = if path.is_empty() {
                k.clone()
            } else {
                format!("{path}/{k}")
            };
            collect_rows(v, run, &path, rows);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_are_paths_and_columns_are_last_keys() {
        let dir = cpose_core::testing::TempDir::new("table");
        let (a, b) = (dir.join("rm30"), dir.join("rm60"));
        for (d, rot) in [(&a, 0.25), (&b, 12.5)] {
            std::fs::create_dir_all(d).unwrap();
            std::fs::write(
                d.join("metrics.json"),
                format!(
                    r#"{{"synthetic": {{"posenet": {{"rot_err_deg": {rot}, "psnr_db": 27.123456, "iterations": 2000, "refined": null}},
                       "barf": {{"rot_err_deg": 30.0}}}}}}"#
                ),
            )
            .unwrap();
        }
        let table = metrics_table(&[a, b.clone()], &[]).unwrap();
        let expected = "\
| run | iterations | psnr_db | refined | rot_err_deg |
|---|---|---|---|---|
| rm30 synthetic/barf | | | | 30.00 |
| rm30 synthetic/posenet | 2000 | 27.12 | | 0.2500 |
| rm60 synthetic/barf | | | | 30.00 |
| rm60 synthetic/posenet | 2000 | 27.12 | | 12.50 |
";
        assert_eq!(table, expected);
        let chosen = metrics_table(std::slice::from_ref(&b), &["rot_err_deg".to_owned()]).unwrap();
        assert!(chosen.starts_with("| run | rot_err_deg |\n"), "{chosen}");
        let err = metrics_table(&[b], &["rot_err".to_owned()]).unwrap_err();
        assert!(
            format!("{err:#}").contains(
                "no run has the metric \"rot_err\" (metrics: iterations, psnr_db, refined, rot_err_deg)"
            ),
            "{err:#}"
        );
        let err = metrics_table(&[dir.join("missing")], &[]).unwrap_err();
        assert!(
            format!("{err:#}").contains("missing/metrics.json"),
            "{err:#}"
        );
    }

    #[test]
    fn integers_print_as_integers_and_other_numbers_keep_four_digits() {
        let dir = cpose_core::testing::TempDir::new("table-int");
        let run = dir.join("slam");
        std::fs::create_dir_all(&run).unwrap();
        std::fs::write(
            run.join("metrics.json"),
            r#"{"baseline": {"frames": 500, "lost_frames": 0, "held_out_poses": 129,
                "big": 12345678901, "negative": -3, "ate_rmse_cm": 500.0, "psnr_db": 27.123456,
                "ratio": 0.000123, "zero": 0.0, "fit_stop": "plateau", "fit_converged": false}}"#,
        )
        .unwrap();
        let table = metrics_table(&[run], &[]).unwrap();
        let expected = "\
| run | ate_rmse_cm | big | fit_converged | fit_stop | frames | held_out_poses | lost_frames | negative | psnr_db | ratio | zero |
|---|---|---|---|---|---|---|---|---|---|---|---|
| slam baseline | 500.0 | 12345678901 | false | plateau | 500 | 129 | 0 | -3 | 27.12 | 1.230e-4 | 0 |
";
        assert_eq!(table, expected);
    }
}
