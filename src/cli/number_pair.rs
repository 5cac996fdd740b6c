//! Two numbers written `A,B` on the command line (a move U,V in px, a step DX,DY in mm).

/// `0.5,-0.1` as (0.5, −0.1); `example` shows the form in the error (`U,V in px, e.g. 0.5,0`).
pub fn number_pair(text: &str, example: &str) -> Result<(f64, f64), String> {
    let bad = || format!("'{text}': expected {example}");
    let (a, b) = text.split_once(',').ok_or_else(bad)?;
    let number = |t: &str| t.trim().parse::<f64>().ok().filter(|x| x.is_finite());
    Ok((number(a).ok_or_else(bad)?, number(b).ok_or_else(bad)?))
}
