//! Checks on the text of a STEP file before any third-party parser sees it.
//!
//! ruststep's parser descends once per parenthesis, so a file with tens of thousands of
//! nested parentheses overflows the parse thread's stack, which aborts the whole process
//! (no `catch_unwind` can stop it); it also panics on integers and exponents that do not
//! fit an `i64`, and reads `1.0E400` as infinity, which truck's tessellator then chases
//! without end. [`check`] walks the file once, without recursion, and refuses all of these
//! with the line and the entity they are in. It also refuses points whose bounding box is
//! too large for its diagonal to be a number, since every distance the encoder measures
//! would then be infinite too.
//!
//! When ruststep still rejects the file, [`locate_syntax_error`] finds the first DATA
//! statement it cannot parse on its own, so the message points at the damage rather than
//! at the `DATA;` line where ruststep's parse of the whole section gave up.

use glam::DVec3;
use truck_stepio::r#in::ruststep::parser::exchange::entity_instance;

/// Deepest parenthesis nesting accepted. Real files need about five (a complex instance
/// holding a list of lists of control points); ruststep needs a few kilobytes of stack per
/// level, so this keeps its parse far from the end of the parse thread's stack.
pub const MAX_NESTING: usize = 64;

/// A problem at a line of the file (1-based).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TextProblem {
    pub line: usize,
    pub detail: String,
}

impl std::fmt::Display for TextProblem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "line {}: {}", self.line, self.detail)
    }
}

/// The statement the scanner is in: where it starts and what it is, for messages.
#[derive(Default)]
struct Statement<'a> {
    line: usize,
    /// `#id` of an instance, when the statement is one.
    id: Option<&'a str>,
    seen_equals: bool,
    /// First keyword after `=` (or the first keyword of a header statement).
    name: Option<&'a str>,
    /// The coordinates of a CARTESIAN_POINT.
    coordinates: Vec<f64>,
}

impl Statement<'_> {
    /// `#12 = CARTESIAN_POINT`, `FILE_NAME`, or `a statement` when nothing is known yet.
    fn label(&self) -> String {
        match (self.id, self.name) {
            (Some(id), Some(name)) => format!("#{id} = {name}"),
            (Some(id), None) => format!("#{id}"),
            (None, Some(name)) => name.to_string(),
            (None, None) => "a statement".to_string(),
        }
    }
}

/// One extreme of the points' box along one axis: the value and where its point is.
#[derive(Clone, Copy)]
struct Extreme {
    value: f64,
    line: usize,
}

/// Checks the whole text (header and data): nesting depth, numbers ruststep can read into
/// finite values, and a finite bounding-box diagonal of the CARTESIAN_POINTs. Linear in
/// the file's size, no recursion.
pub fn check(text: &str) -> Result<(), TextProblem> {
    let b = text.as_bytes();
    let mut i = 0;
    let mut line = 1usize;
    let mut depth = 0usize;
    let mut stmt: Option<Statement> = None;
    let mut lo: [Option<Extreme>; 3] = [None; 3];
    let mut hi: [Option<Extreme>; 3] = [None; 3];
    while i < b.len() {
        let c = b[i];
        if c == b'\n' {
            line += 1;
            i += 1;
            continue;
        }
        if c.is_ascii_whitespace() {
            i += 1;
            continue;
        }
        if c == b'/' && b.get(i + 1) == Some(&b'*') {
            let end = text[i + 2..].find("*/").map_or(b.len(), |k| i + 2 + k + 2);
            line += b[i..end].iter().filter(|&&x| x == b'\n').count();
            i = end;
            continue;
        }
        let s = stmt.get_or_insert_with(|| Statement {
            line,
            ..Default::default()
        });
        let problem = |s: &Statement, detail: String| TextProblem {
            line: s.line,
            detail: format!("{}: {detail}", s.label()),
        };
        match c {
            b'\'' => {
                i = after_string(b, i, &mut line);
            }
            // A binary literal: hex digits, not a number.
            b'"' => {
                let end = text[i + 1..].find('"').map_or(b.len(), |k| i + 1 + k + 1);
                line += b[i..end].iter().filter(|&&x| x == b'\n').count();
                i = end;
            }
            b'(' => {
                depth += 1;
                if depth > MAX_NESTING {
                    return Err(problem(
                        s,
                        format!("parentheses nested deeper than {MAX_NESTING} levels"),
                    ));
                }
                i += 1;
            }
            b')' => {
                depth = depth.saturating_sub(1);
                i += 1;
            }
            b';' => {
                if s.name == Some("CARTESIAN_POINT") && (2..=3).contains(&s.coordinates.len()) {
                    for (k, &v) in s.coordinates.iter().enumerate() {
                        let e = Extreme {
                            value: v,
                            line: s.line,
                        };
                        if lo[k].is_none_or(|x| v < x.value) {
                            lo[k] = Some(e);
                        }
                        if hi[k].is_none_or(|x| v > x.value) {
                            hi[k] = Some(e);
                        }
                    }
                }
                // A `;` inside parentheses belongs to broken text; the statement ends
                // anyway so that the next one is named right.
                depth = 0;
                stmt = None;
                i += 1;
            }
            b'=' => {
                s.seen_equals = true;
                i += 1;
            }
            b'#' => {
                let j = i + 1 + b[i + 1..].iter().take_while(|x| x.is_ascii_digit()).count();
                let digits = &text[i + 1..j];
                if !digits.is_empty() {
                    if digits.parse::<u64>().is_err() {
                        return Err(problem(
                            s,
                            format!("the instance number #{digits} is too large"),
                        ));
                    }
                    if s.id.is_none() && !s.seen_equals && s.name.is_none() {
                        s.id = Some(digits);
                    }
                }
                i = j.max(i + 1);
            }
            c if c.is_ascii_alphabetic() || c == b'_' => {
                let j = i + b[i..]
                    .iter()
                    .take_while(|x| x.is_ascii_alphanumeric() || **x == b'_' || **x == b'-')
                    .count();
                if s.name.is_none() && (s.seen_equals || s.id.is_none()) {
                    s.name = Some(&text[i..j]);
                }
                i = j;
            }
            c if c.is_ascii_digit()
                || ((c == b'+' || c == b'-') && b.get(i + 1).is_some_and(u8::is_ascii_digit)) =>
            {
                let (j, number) = scan_number(b, i);
                let token = &text[i..j];
                match number {
                    Number::Integer if token.parse::<i64>().is_err() => {
                        return Err(problem(
                            s,
                            format!("the integer {token} does not fit 64 bits"),
                        ));
                    }
                    Number::Integer => {}
                    Number::Real(None) => {
                        return Err(problem(
                            s,
                            format!("the exponent of the number {token} does not fit 64 bits"),
                        ));
                    }
                    Number::Real(Some(v)) if !v.is_finite() => {
                        return Err(problem(
                            s,
                            format!("the number {token} is not finite (too large for f64)"),
                        ));
                    }
                    Number::Real(Some(v)) => {
                        if s.name == Some("CARTESIAN_POINT") {
                            s.coordinates.push(v);
                        }
                    }
                }
                i = j;
            }
            _ => i += 1,
        }
    }
    check_extent(&lo, &hi)
}

/// A number token of the file.
enum Number {
    Integer,
    /// The value ruststep reads, `None` when ruststep cannot read its exponent.
    Real(Option<f64>),
}

/// Scans `[sign] digits [. digits [E [sign] digits]]` from `i`: its end and what it is.
fn scan_number(b: &[u8], i: usize) -> (usize, Number) {
    let digits = |from: usize| from + b[from..].iter().take_while(|x| x.is_ascii_digit()).count();
    let start = if b[i] == b'+' || b[i] == b'-' {
        i + 1
    } else {
        i
    };
    let int_end = digits(start);
    if b.get(int_end) != Some(&b'.') {
        return (int_end, Number::Integer);
    }
    let frac_end = digits(int_end + 1);
    let mut end = frac_end;
    let mut exponent = 0i64;
    if matches!(b.get(frac_end), Some(b'E' | b'e')) {
        let sign_at = frac_end + 1;
        let exp_start = match b.get(sign_at) {
            Some(b'+' | b'-') => sign_at + 1,
            _ => sign_at,
        };
        let exp_end = digits(exp_start);
        if exp_end > exp_start {
            end = exp_end;
            let text = std::str::from_utf8(&b[exp_start..exp_end]).unwrap_or("");
            match text.parse::<i64>() {
                Ok(e) if b[sign_at] == b'-' => exponent = -e,
                Ok(e) => exponent = e,
                Err(_) => return (end, Number::Real(None)),
            }
        }
    }
    // Read the way ruststep reads it: integral part, fraction and exponent.
    let int = std::str::from_utf8(&b[start..int_end]).unwrap_or("0");
    let frac = std::str::from_utf8(&b[int_end + 1..frac_end]).unwrap_or("");
    let value = format!("{int}.{frac}e{exponent}").parse::<f64>().ok();
    (end, Number::Real(value))
}

/// An error when the CARTESIAN_POINTs' bounding box has no finite diagonal, naming the
/// points at the ends of its longest side.
fn check_extent(lo: &[Option<Extreme>; 3], hi: &[Option<Extreme>; 3]) -> Result<(), TextProblem> {
    let mut size = DVec3::ZERO;
    for k in 0..3 {
        if let (Some(l), Some(h)) = (lo[k], hi[k]) {
            size[k] = h.value - l.value;
        }
    }
    if size.length().is_finite() {
        return Ok(());
    }
    let k = (0..3)
        .max_by(|&a, &b| size[a].total_cmp(&size[b]))
        .unwrap_or(0);
    let (Some(l), Some(h)) = (lo[k], hi[k]) else {
        return Ok(());
    };
    let far = if h.value.abs() >= l.value.abs() { h } else { l };
    Err(TextProblem {
        line: far.line,
        detail: format!(
            "CARTESIAN_POINT coordinate {:e}: the points span {:e} to {:e} (lines {} and \
             {}), a box whose diagonal is too large for f64",
            far.value, l.value, h.value, l.line, h.line
        ),
    })
}

/// The first instance of the DATA section(s) that ruststep cannot parse on its own, with
/// its line; `None` when each parses (the damage is elsewhere: the header or a section
/// keyword).
pub fn locate_syntax_error(text: &str) -> Option<TextProblem> {
    let b = text.as_bytes();
    let mut i = 0;
    let mut line = 1usize;
    let mut in_data = false;
    // Start of the statement being read (its first significant byte) and its line.
    let mut start: Option<(usize, usize)> = None;
    while i < b.len() {
        match b[i] {
            b'\n' => {
                line += 1;
                i += 1;
            }
            c if c.is_ascii_whitespace() => i += 1,
            b'/' if b.get(i + 1) == Some(&b'*') => {
                let end = text[i + 2..].find("*/").map_or(b.len(), |k| i + 2 + k + 2);
                line += b[i..end].iter().filter(|&&x| x == b'\n').count();
                i = end;
            }
            b'\'' => {
                start.get_or_insert((i, line));
                i = after_string(b, i, &mut line);
            }
            b';' => {
                let (from, at) = start.take().unwrap_or((i, line));
                let stmt = &text[from..=i];
                let keyword = stmt.trim_end_matches(';').trim();
                if in_data {
                    if keyword == "ENDSEC" {
                        in_data = false;
                    } else if !parses_alone(stmt) {
                        return Some(TextProblem {
                            line: at,
                            detail: format!("cannot parse `{}`", excerpt(stmt)),
                        });
                    }
                } else if keyword == "DATA" || keyword.starts_with("DATA(") {
                    in_data = true;
                }
                i += 1;
            }
            _ => {
                start.get_or_insert((i, line));
                i += 1;
            }
        }
    }
    match (in_data, start) {
        // The last instance has no `;`.
        (true, Some((from, at))) => Some(TextProblem {
            line: at,
            detail: format!(
                "the file ends inside `{}` (no `;` and no ENDSEC)",
                excerpt(&text[from..])
            ),
        }),
        _ => None,
    }
}

/// Whether ruststep parses `stmt` (one instance with its `;`) completely.
fn parses_alone(stmt: &str) -> bool {
    matches!(entity_instance(stmt), Ok((rest, _)) if rest.trim().is_empty())
}

/// The start of a statement on one line, at most 60 characters, for messages.
fn excerpt(stmt: &str) -> String {
    let one_line: String = stmt.split_whitespace().collect::<Vec<_>>().join(" ");
    match one_line.char_indices().nth(60) {
        Some((k, _)) => format!("{}...", &one_line[..k]),
        None => one_line,
    }
}

/// The index after the string literal that opens at `b[open]` (a quote; `''` inside is a
/// quote, not the end), counting the lines it spans into `line`.
fn after_string(b: &[u8], open: usize, line: &mut usize) -> usize {
    let mut i = open + 1;
    while i < b.len() {
        if b[i] == b'\'' {
            if b.get(i + 1) == Some(&b'\'') {
                i += 2;
                continue;
            }
            break;
        }
        if b[i] == b'\n' {
            *line += 1;
        }
        i += 1;
    }
    i + 1
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file(data: &str) -> String {
        format!(
            "ISO-10303-21;\nHEADER;\nFILE_NAME('a;(b','',(''),(''),'','','');\nENDSEC;\nDATA;\n\
             {data}ENDSEC;\nEND-ISO-10303-21;\n"
        )
    }

    #[test]
    fn ordinary_files_pass() {
        let text = file(
            "#1 = CARTESIAN_POINT('((( #9',(0.,-1.5E2,+2.0E-3));\n\
             /* ((((( #99999999999999999999999 */\n\
             #2 = ( LENGTH_UNIT() NAMED_UNIT(*) SI_UNIT(.MILLI.,.METRE.) );\n\
             #3 = B_SPLINE_SURFACE_WITH_KNOTS('',1,1,((#1,#1),(#1,#1)),.UNSPECIFIED.,.F.,\
             .F.,.F.,(2),(2),(0.,1.),(0.,1.),.UNSPECIFIED.);\n",
        );
        assert_eq!(check(&text), Ok(()));
        assert_eq!(locate_syntax_error(&text), None);
    }

    /// 50 000 nested parentheses are refused without recursion (the scanner would overflow
    /// no stack either way; ruststep's parser would), naming the line and the instance.
    #[test]
    fn deep_nesting_is_refused_with_its_line() {
        let deep = format!(
            "#1 = CARTESIAN_POINT('',(0.,0.,0.));\n#2 = CARTESIAN_POINT('',{}{});\n",
            "(".repeat(50_000),
            ")".repeat(50_000)
        );
        let e = check(&file(&deep)).unwrap_err();
        assert_eq!(e.line, 7, "{e}");
        assert!(
            e.detail
                .starts_with("#2 = CARTESIAN_POINT: parentheses nested deeper"),
            "{e}"
        );
        // A header statement is checked too.
        let header = format!(
            "ISO-10303-21;\nHEADER;\nFILE_NAME({}'a'{});\nENDSEC;\n",
            "(".repeat(100),
            ")".repeat(100)
        );
        let e = check(&header).unwrap_err();
        assert_eq!(
            (e.line, e.detail.starts_with("FILE_NAME:")),
            (3, true),
            "{e}"
        );
        // Exactly the limit passes.
        let ok = format!(
            "#1 = A({}1{});\n",
            "(".repeat(MAX_NESTING - 1),
            ")".repeat(MAX_NESTING - 1)
        );
        assert_eq!(check(&file(&ok)), Ok(()));
    }

    #[test]
    fn non_finite_and_unreadable_numbers_are_refused() {
        let cases = [
            (
                "#7 = CARTESIAN_POINT('',(1.0E400,0.,0.));\n",
                "#7 = CARTESIAN_POINT",
                "1.0E400",
            ),
            ("#8 = VECTOR('',#7,-9.E999);\n", "#8 = VECTOR", "-9.E999"),
            (
                "#9 = CIRCLE('',#4,1.E-99999999999999999999);\n",
                "#9 = CIRCLE",
                "exponent",
            ),
            ("#10 = B('',99999999999999999999);\n", "#10 = B", "64 bits"),
            (
                "#11 = B('',#99999999999999999999);\n",
                "#11 = B",
                "too large",
            ),
        ];
        for (data, label, what) in cases {
            let e = check(&file(data)).unwrap_err();
            assert_eq!(e.line, 6, "{e}");
            assert!(
                e.detail.starts_with(label) && e.detail.contains(what),
                "{e}"
            );
        }
    }

    /// Finite points 1.7e308 apart: their box's diagonal is infinite, named by the point
    /// farther out.
    #[test]
    fn points_whose_box_overflows_are_refused() {
        let data = "#1 = CARTESIAN_POINT('',(-1.7E308,0.,0.));\n\
                    #2 = CARTESIAN_POINT('',(0.,0.,0.));\n\
                    #3 = CARTESIAN_POINT('',(1.7E308,0.,1.));\n";
        let e = check(&file(data)).unwrap_err();
        assert!(e.detail.contains("too large for f64"), "{e}");
        assert!(e.line == 6 || e.line == 8, "{e}");
        // 1e154 squared overflows too: the diagonal's length is what the encoder measures.
        let data =
            "#1 = CARTESIAN_POINT('',(0.,0.,0.));\n#2 = CARTESIAN_POINT('',(0.,2.E154,0.));\n";
        assert_eq!(check(&file(data)).unwrap_err().line, 7);
        let data =
            "#1 = CARTESIAN_POINT('',(0.,0.,0.));\n#2 = CARTESIAN_POINT('',(0.,1.E150,0.));\n";
        assert_eq!(check(&file(data)), Ok(()));
    }

    /// The damaged instance is named with its line, not the `DATA;` line.
    #[test]
    fn syntax_errors_point_at_the_damaged_instance() {
        let text = file(
            "#1 = CARTESIAN_POINT('',(0.,0.,0.));\n#2 = DIRECTION('',(1.,0.,0.));\n\
             #3 = VECTOR('',#2,,1.);\n#4 = LINE('',#1,#3);\n",
        );
        let e = locate_syntax_error(&text).unwrap();
        assert_eq!(e.line, 8, "{e}");
        assert!(e.detail.contains("#3 = VECTOR('',#2,,1.);"), "{e}");
        let cut = file("#1 = CARTESIAN_POINT('',(0.,0.,0.));\n#2 = DIRECTION('',(1.,");
        let cut = cut.split("ENDSEC;\nEND").next().unwrap();
        let e = locate_syntax_error(cut).unwrap();
        assert_eq!(e.line, 7, "{e}");
    }
}
