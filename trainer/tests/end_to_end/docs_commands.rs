//! Docs that cannot drift (issue 52 item 3): every `cbd …` command in a fenced `sh` block of the
//! README and of docs/guide/*.md is parsed by the command line the binary uses, so a flag or a
//! value form that does not exist fails here, naming the page and the line; the README's worked
//! example is run end to end on the shipped examples.

use clap::Parser;
use std::path::{Path, PathBuf};
use std::process::Command;

const CBD: &str = env!("CARGO_BIN_EXE_cbd");

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

/// The README and every guide page.
fn pages() -> Vec<PathBuf> {
    let mut pages = vec![repo().join("README.md")];
    let mut guide: Vec<PathBuf> = std::fs::read_dir(repo().join("docs/guide"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    guide.sort();
    assert!(guide.len() >= 8, "docs/guide has {} pages", guide.len());
    pages.extend(guide);
    pages
}

/// A documented command: where it stands and its words as the shell would split them.
struct DocumentedCommand {
    place: String,
    words: Vec<String>,
}

/// The fenced `sh` blocks' commands of `text`: continuation lines joined, `NAME=value` lines
/// substituted into the lines after them, comments and what follows a pipe or redirection cut.
fn commands_of(page: &Path, text: &str) -> Vec<DocumentedCommand> {
    let mut out = Vec::new();
    let mut in_sh = false;
    let mut vars: Vec<(String, String)> = Vec::new();
    let mut pending: Option<(usize, String)> = None;
    for (n, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        if let Some(lang) = trimmed.strip_prefix("```") {
            in_sh = !in_sh && matches!(lang.trim(), "sh" | "bash" | "shell");
            vars.clear();
            continue;
        }
        if !in_sh {
            continue;
        }
        let (start, mut joined) = pending.take().unwrap_or((n + 1, String::new()));
        joined.push_str(line.trim());
        if let Some(stripped) = joined.strip_suffix('\\') {
            pending = Some((start, format!("{} ", stripped.trim_end())));
            continue;
        }
        let words = shell_words(&joined);
        if words.len() == 1 {
            if let Some((name, value)) = words[0].split_once('=') {
                if !name.is_empty() && name.chars().all(|c| c.is_ascii_uppercase() || c == '_') {
                    vars.push((format!("${name}"), value.to_string()));
                    continue;
                }
            }
        }
        // A leading `NAME=value` environment prefix is the shell's, not cbd's.
        let words: Vec<String> = words.into_iter().skip_while(|w| w.contains('=') && !w.starts_with('-')).collect();
        if words.first().map(String::as_str) != Some("cbd") {
            continue;
        }
        let words = words.into_iter().map(|w| vars.iter().fold(w, |w, (name, value)| w.replace(name.as_str(), value))).collect();
        out.push(DocumentedCommand { place: format!("{}:{start}", page.strip_prefix(repo()).unwrap().display()), words });
    }
    out
}

/// Splits a line as sh does for the plain cases the docs use: quotes, a comment, and the end of
/// the command at a pipe, a redirection, `;` or `&&`.
fn shell_words(line: &str) -> Vec<String> {
    let mut words = Vec::new();
    let mut word: Option<String> = None;
    let mut quote: Option<char> = None;
    for c in line.chars() {
        match (quote, c) {
            (Some(q), c) if c == q => quote = None,
            (Some(_), c) => word.get_or_insert_with(String::new).push(c),
            (None, '\'' | '"') => {
                quote = Some(c);
                word.get_or_insert_with(String::new);
            }
            (None, '#') if word.is_none() => break,
            (None, '|' | '>' | '<' | ';' | '&') => break,
            (None, c) if c.is_whitespace() => words.extend(word.take()),
            (None, c) => word.get_or_insert_with(String::new).push(c),
        }
    }
    words.extend(word);
    words
}

#[test]
fn every_documented_command_parses() {
    let mut parsed = 0;
    let mut wrong = Vec::new();
    for page in pages() {
        let text = std::fs::read_to_string(&page).unwrap();
        for command in commands_of(&page, &text) {
            match cbd_trainer::cli::Cli::try_parse_from(&command.words) {
                Ok(_) => parsed += 1,
                Err(e) if matches!(e.kind(), clap::error::ErrorKind::DisplayHelp | clap::error::ErrorKind::DisplayVersion) => parsed += 1,
                Err(e) => {
                    wrong.push(format!("{}: `{}`: {}", command.place, command.words.join(" "), e.to_string().lines().next().unwrap_or("")))
                }
            }
        }
    }
    assert!(wrong.is_empty(), "documented commands the CLI refuses:\n{}", wrong.join("\n"));
    assert!(parsed >= 30, "only {parsed} documented commands found: is the extraction broken?");
}

#[test]
fn the_extraction_sees_continuations_variables_and_comments() {
    let page = repo().join("README.md");
    let text = "```sh\nM=examples/x.toml\ncbd fit --model $M \\\n    --data a.csv --out b.blob   # note\ncat a > b\n```\n```text\ncbd not a command\n```\n";
    let found = commands_of(&page, text);
    assert_eq!(found.len(), 1);
    assert_eq!(found[0].words, ["cbd", "fit", "--model", "examples/x.toml", "--data", "a.csv", "--out", "b.blob"]);
    assert_eq!(found[0].place, "README.md:3");
    assert_eq!(
        shell_words("cbd simulate --effect \"bump:centre=1;2\" --out x.csv | head"),
        ["cbd", "simulate", "--effect", "bump:centre=1;2", "--out", "x.csv"]
    );
    // A flag that does not exist is refused (what the first test relies on).
    assert!(cbd_trainer::cli::Cli::try_parse_from(["cbd", "fit", "--joint-widths", "1"]).is_err());
}

/// The README's worked example ("Calibrating your own data"), run as written in a scratch folder
/// that sees the shipped examples: every command succeeds.
#[test]
fn the_readme_worked_example_runs() {
    let readme = std::fs::read_to_string(repo().join("README.md")).unwrap();
    let section = readme.split("## Calibrating your own data").nth(1).unwrap();
    let block = section.split("```sh\n").nth(1).unwrap().split("```").next().unwrap();
    let commands = commands_of(&repo().join("README.md"), &format!("```sh\n{block}```\n"));
    assert!(commands.len() >= 6, "{} commands in the worked example", commands.len());
    let dir = std::env::temp_dir().join(format!("cbd-docs-example-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    std::os::unix::fs::symlink(repo().join("examples"), dir.join("examples")).unwrap();
    for command in &commands {
        let out = Command::new(CBD).args(&command.words[1..]).arg("--quiet").current_dir(&dir).output().unwrap();
        let out = if out.status.success() || !String::from_utf8_lossy(&out.stderr).contains("--quiet") {
            out
        } else {
            Command::new(CBD).args(&command.words[1..]).current_dir(&dir).output().unwrap()
        };
        assert!(out.status.success(), "{}: `{}` failed:\n{}", command.place, command.words.join(" "), String::from_utf8_lossy(&out.stderr));
    }
    let _ = std::fs::remove_dir_all(&dir);
}
