//! The last check of a model file: every number in it, whatever field holds it, finite and within
//! ±[`MAX_MAGNITUDE`] (README "Model files"). Each section checks its own fields first, with its
//! own message; this walk over the whole TOML catches whatever a section does not (a field added
//! later, a value only a unit conversion reads), naming the field by its path.

use crate::limits::MAX_MAGNITUDE;

/// The first number of `text` (already parsed once: valid TOML) that is not finite or beyond
/// ±[`MAX_MAGNITUDE`]: its field (`[chain] tool.translation[3]`, 1-based indices) and message.
pub(super) fn out_of_range(text: &str) -> Option<(String, String)> {
    let table: toml::Table = toml::from_str(text).ok()?;
    let mut path = Vec::new();
    first_bad(&toml::Value::Table(table), &mut path)
}

fn first_bad(value: &toml::Value, path: &mut Vec<String>) -> Option<(String, String)> {
    match value {
        toml::Value::Float(v) if !(v.is_finite() && v.abs() <= MAX_MAGNITUDE) => {
            let what = if v.is_finite() { format!("beyond ±{MAX_MAGNITUDE:e}") } else { "not a finite number".into() };
            Some((field_name(path), format!("{} is {what}", crate::error::number(*v))))
        }
        toml::Value::Table(t) => t.iter().find_map(|(k, v)| {
            path.push(k.clone());
            let bad = first_bad(v, path);
            path.pop();
            bad
        }),
        toml::Value::Array(a) => a.iter().enumerate().find_map(|(i, v)| {
            path.push(format!("[{}]", i + 1));
            let bad = first_bad(v, path);
            path.pop();
            bad
        }),
        _ => None,
    }
}

/// `["chain", "tool", "translation", "[3]"]` → `[chain] tool.translation[3]`.
fn field_name(path: &[String]) -> String {
    let mut out = String::new();
    for (k, part) in path.iter().enumerate() {
        if part.starts_with('[') {
            out += part;
        } else if k == 0 && path.len() > 1 {
            out += &format!("[{part}] ");
        } else {
            if !(out.is_empty() || out.ends_with(' ')) {
                out.push('.');
            }
            out += part;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_number_of_any_field_is_checked() {
        assert_eq!(out_of_range("a = 1\n[b]\nc = [1.0, -1e100]\n"), None);
        let (field, message) = out_of_range("a = 1\n[chain]\ntool = { translation = [0, 0, nan] }\n").unwrap();
        assert_eq!((field.as_str(), message.as_str()), ("[chain] tool.translation[3]", "NaN is not a finite number"));
        let (field, message) = out_of_range("[measurements]\njoint_limits = [[-1e300, 1e300]]\n").unwrap();
        assert_eq!((field.as_str(), message.as_str()), ("[measurements] joint_limits[1][1]", "-1e300 is beyond ±1e100"));
        assert_eq!(out_of_range("yaw = inf\n").unwrap().0, "yaw");
    }
}
