//! The TOML parser's errors as one line naming where and which field: line, column and the key
//! the offending value belongs to (`[chain] tool.translation`), so that a type or length error
//! deep in an inline table names its field and not only its position.

/// The TOML parser's error on one line: where (line and column of its span), which field, and
/// what, the message's quotes of the file cut to excerpts (a 1 MiB line is not echoed).
pub(super) fn toml_message(e: &toml::de::Error, text: &str) -> String {
    let what = e.message().trim_end().split('\n').map(|line| crate::error::excerpt_of(line, 200)).collect::<Vec<_>>().join("; ");
    match e.span() {
        Some(span) => {
            let start = span.start.min(text.len());
            let before = &text.as_bytes()[..start];
            let line = 1 + before.iter().filter(|&&b| b == b'\n').count();
            let column = 1 + before.iter().rev().take_while(|&&b| b != b'\n').count();
            let field = field_at(text, start).map(|f| format!(" ({})", crate::error::excerpt(&f))).unwrap_or_default();
            format!("TOML parse error at line {line}, column {column}{field}: {what}")
        }
        None => format!("TOML parse error: {what}"),
    }
}

/// The field whose value contains byte `offset`: the keys of the enclosing inline tables and
/// arrays and the value's own key, dotted, after the table header above it
/// (`[chain] tool.translation`). A forward scan that skips strings and comments; `None` where no
/// key holds the offset (e.g. a table header).
fn field_at(text: &str, offset: usize) -> Option<String> {
    let b = text.as_bytes();
    let mut header = String::new();
    // Open arrays and inline tables with the key each is the value of.
    let mut stack: Vec<(u8, Option<String>)> = Vec::new();
    let mut key: Option<String> = None;
    // At a line's start at top level, or after `{` or `,` inside an inline table.
    let mut expect_key = true;
    let mut i = 0;
    while i < b.len().min(offset) {
        let c = b[i];
        match c {
            b'#' => {
                while i < b.len() && b[i] != b'\n' {
                    i += 1;
                }
                continue;
            }
            b'"' | b'\'' => {
                i = string_end(b, i);
                continue;
            }
            b'\n' if stack.is_empty() => {
                expect_key = true;
                key = None;
            }
            b'[' if stack.is_empty() && expect_key => {
                let end = b[i..].iter().position(|&x| x == b'\n').map_or(b.len(), |p| i + p);
                header = text[i..end].split('#').next().unwrap_or("").trim().to_string();
                i = end;
                continue;
            }
            b'[' | b'{' => {
                stack.push((c, key.take()));
                expect_key = c == b'{';
            }
            b']' | b'}' => {
                if let Some((_, k)) = stack.pop() {
                    key = k;
                }
            }
            b',' => {
                if matches!(stack.last(), Some((b'{', _))) {
                    expect_key = true;
                }
                key = None;
            }
            c if expect_key && !c.is_ascii_whitespace() => {
                let eq = key_end(b, i);
                // By bytes: the clamped end can fall inside a multi-byte character (fuzz: "Р").
                key = Some(String::from_utf8_lossy(&b[i..eq]).trim().to_string());
                expect_key = false;
                i = eq + 1;
                continue;
            }
            _ => {}
        }
        i += 1;
    }
    let keys: Vec<&str> = stack.iter().filter_map(|(_, k)| k.as_deref()).chain(key.as_deref()).collect();
    if keys.is_empty() {
        return None;
    }
    let header = if header.is_empty() { String::new() } else { format!("{header} ") };
    Some(format!("{header}{}", keys.join(".")))
}

/// The byte after the string starting at `start` (basic or literal, one-line or triple-quoted).
fn string_end(b: &[u8], start: usize) -> usize {
    let quote = b[start];
    let triple = b.len() >= start + 3 && b[start + 1] == quote && b[start + 2] == quote;
    let mut i = start + if triple { 3 } else { 1 };
    while i < b.len() {
        if b[i] == b'\\' && quote == b'"' {
            i += 2;
            continue;
        }
        if b[i] == quote && (!triple || (i + 2 < b.len() && b[i + 1] == quote && b[i + 2] == quote)) {
            return i + if triple { 3 } else { 1 };
        }
        if b[i] == b'\n' && !triple {
            return i;
        }
        i += 1;
    }
    b.len()
}

/// The `=` ending the key that starts at `start` (quoted parts skipped), or the line's end.
fn key_end(b: &[u8], start: usize) -> usize {
    let mut i = start;
    while i < b.len() && b[i] != b'=' && b[i] != b'\n' {
        if b[i] == b'"' || b[i] == b'\'' {
            i = string_end(b, i);
            continue;
        }
        i += 1;
    }
    i.min(b.len().saturating_sub(1)).max(start)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Fuzz (csv_import target, model-file branch): a file of one two-byte character panicked
    /// slicing inside it; a multi-byte key is named, never split.
    #[test]
    fn a_key_of_multi_byte_characters_is_never_split() {
        for text in ["\u{420}", "\u{420}\u{420}\n", "a = 1\n\u{420}", "[t]\n\u{1F600} = \"x"] {
            for offset in 0..=text.len() {
                let _ = field_at(text, offset);
            }
        }
        assert_eq!(field_at("\u{420}\u{421} = [1, 2\n", 10).as_deref(), Some("\u{420}\u{421}"));
        assert!(crate::data::model_file::parse_model_file("\u{420}", std::path::Path::new("m.toml")).is_err());
    }

    #[test]
    fn the_field_of_a_value_is_named_through_inline_tables_and_arrays() {
        let text = "length_unit = \"mm\"\n[chain]\ntool = { translation = [0, 0, 31, 99], points = [[1, 2, 3], [4, 5, 6, 7]] }\n\
                    joint_limits = [\n  [1, 2],\n  [3, 4, 5],\n]\n";
        let at = |needle: &str| field_at(text, text.find(needle).unwrap());
        assert_eq!(at("[0, 0, 31").as_deref(), Some("[chain] tool.translation"));
        assert_eq!(at("[4, 5").as_deref(), Some("[chain] tool.points"));
        assert_eq!(at("[3, 4, 5]").as_deref(), Some("[chain] joint_limits"));
        assert_eq!(at("\"mm\"").as_deref(), Some("length_unit"));
        assert_eq!(field_at(text, text.find("[chain]").unwrap()), None);
    }
}
