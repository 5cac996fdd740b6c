//! The dashboard prints a value and its error as the server does: `plusMinus`, `lengthPm` and
//! `valuePm` of `src/dashboard/assets/common.js` against `report::plus_minus`, `length_pm` and
//! `value_pm`, on one list of cases run through both (the JavaScript by Node.js, as the browser
//! tests need it). A reader who compares the dashboard's table with `ffdic compare`'s must read
//! the same digits.

use ffdic::report::{length_pm, plus_minus, value_pm};
use rand::{Rng, SeedableRng};
use std::io::Write;
use std::process::{Command, Stdio};

/// One formatting call: which function, the value, and its error (`None`: no error stated; the
/// server's functions take NaN there, the dashboard's `null`).
type Case = (&'static str, f64, Option<f64>);

/// Values and errors over the magnitudes a diagnosis prints (a k1 of 1e-7 to a 1e4 offset),
/// both signs, errors from a thousandth of the value to ten times it, and the edges each
/// function treats apart: a value that rounds to zero (signed "+0.000", never "-0.000"), errors
/// that are powers of ten, a length the debiasing left at zero, no error at all.
fn cases() -> Vec<Case> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(20261128);
    let mut out: Vec<Case> = Vec::new();
    for _ in 0..400 {
        let exponent = rng.gen_range(-7..=4);
        let value =
            rng.gen_range(1.0..10.0) * 10f64.powi(exponent) * [1.0, -1.0][rng.gen_range(0..2)];
        let se = rng.gen_range(1.0..10.0) * 10f64.powi(exponent + rng.gen_range(-3..=1));
        for f in ["plusMinus", "valuePm"] {
            out.push((f, value, Some(se)));
        }
        out.push(("lengthPm", value.abs(), Some(se)));
    }
    for se in [1e-6, 1e-3, 0.01, 1.0, 100.0] {
        for value in [0.0, 3.0 * se, -0.004 * se, 0.004 * se, 123.456 * se] {
            out.push(("plusMinus", value, Some(se)));
            out.push(("valuePm", value, Some(se)));
            out.push(("lengthPm", value, Some(se)));
        }
    }
    for value in [0.5, -0.000123, 12345.6, 1.042e-4, 0.0] {
        out.push(("plusMinus", value, Some(0.0)));
        out.push(("lengthPm", value, Some(0.0)));
        out.push(("valuePm", value, Some(0.0)));
        out.push(("valuePm", value, None));
    }
    out
}

fn on_the_server((function, value, se): &Case) -> String {
    let se = se.unwrap_or(f64::NAN);
    match *function {
        "plusMinus" => plus_minus(*value, se),
        "lengthPm" => length_pm(*value, se),
        "valuePm" => value_pm(*value, se),
        other => panic!("no such formatter: {other}"),
    }
}

/// The dashboard's strings for `cases`, from its own module run by Node.js.
fn in_the_dashboard(cases: &[Case]) -> Vec<String> {
    let common = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("src/dashboard/assets/common.js")
        .canonicalize()
        .expect("common.js");
    let script = format!(
        r#"import {{ plusMinus, lengthPm, valuePm }} from "file://{}";
let input = "";
for await (const chunk of process.stdin) input += chunk;
const formatters = {{ plusMinus, lengthPm, valuePm }};
console.log(JSON.stringify(JSON.parse(input).map(([f, v, e]) => formatters[f](v, e))));"#,
        common.display()
    );
    let mut node = Command::new("node")
        .args(["--input-type=module", "-e", &script])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("this test needs Node.js (`node` on PATH), as the dashboard's browser tests do");
    let input = serde_json::to_vec(cases).expect("cases serialise");
    node.stdin
        .take()
        .expect("stdin")
        .write_all(&input)
        .expect("cases to node");
    let out = node.wait_with_output().expect("node ran");
    assert!(
        out.status.success(),
        "node failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("node printed the strings as JSON")
}

#[test]
fn the_dashboard_prints_values_and_errors_as_the_server_does() {
    let cases = cases();
    let dashboard = in_the_dashboard(&cases);
    assert_eq!(dashboard.len(), cases.len());
    let differ: Vec<String> = cases
        .iter()
        .zip(&dashboard)
        .filter_map(|(case, js)| {
            let rust = on_the_server(case);
            (rust != *js).then(|| format!("{case:?}: server {rust:?}, dashboard {js:?}"))
        })
        .collect();
    assert!(
        differ.is_empty(),
        "{} of {} cases differ:\n{}",
        differ.len(),
        cases.len(),
        differ.join("\n")
    );
}
