//! docs/USAGE.md against the binary's `--help`: every command and every long option the binary
//! lists is named in USAGE.md, and USAGE.md names no option the binary does not take, so that
//! the two cannot drift apart. Also: the links and the repository paths that README.md and
//! docs/USAGE.md name lead to files that exist.

use crate::common::{matfit, root};
use std::collections::BTreeSet;
use std::path::Path;

/// Options USAGE.md names that are not matfit's: cargo's and npm's, in its build and validator
/// commands.
const OTHER_TOOLS: [&str; 2] = ["--release", "--prefix"];

/// Options the binary takes without listing them in `--help` (kept for older scripts) that
/// USAGE.md names; each is checked to be accepted.
const HIDDEN: [(&str, &str); 1] = [("inspect", "--no-register")];

/// `matfit ARGS --help`'s text.
fn help(args: &[&str]) -> String {
    let out = matfit()
        .args(args)
        .arg("--help")
        .output()
        .expect("runs matfit");
    assert!(out.status.success(), "matfit {args:?} --help failed");
    String::from_utf8(out.stdout).unwrap()
}

/// The long options a `--help` text lists: the `--name`s at the start of its option lines
/// (`  -o, --output <OUTPUT>`, `      --spp <N>`), wherever clap wraps their descriptions.
fn listed_options(help: &str) -> BTreeSet<String> {
    help.lines()
        .filter_map(|l| {
            let l = l.trim_start();
            let l = match l.strip_prefix('-') {
                Some(rest) if !rest.starts_with('-') => rest.get(3..)?.trim_start(), // "-o, "
                _ => l,
            };
            let name: String = l
                .strip_prefix("--")?
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '-')
                .collect();
            (!name.is_empty()).then(|| format!("--{name}"))
        })
        .collect()
}

/// The subcommands a `--help` text lists under "Commands:" (without `help`).
fn listed_commands(help: &str) -> Vec<String> {
    help.lines()
        .skip_while(|l| !l.trim_end().ends_with("Commands:"))
        .skip(1)
        .take_while(|l| !l.trim().is_empty())
        .filter(|l| l.starts_with("  ") && !l.starts_with("      "))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|c| *c != "help")
        .map(str::to_string)
        .collect()
}

/// Every command path (`["render"]`, `["bench", "rays"]`, …) and the options each lists.
fn commands() -> Vec<(Vec<String>, BTreeSet<String>)> {
    let mut todo = vec![Vec::<String>::new()];
    let mut all = Vec::new();
    while let Some(path) = todo.pop() {
        let args: Vec<&str> = path.iter().map(String::as_str).collect();
        let text = help(&args);
        for sub in listed_commands(&text) {
            let mut p = path.clone();
            p.push(sub);
            todo.push(p);
        }
        all.push((path, listed_options(&text)));
    }
    all
}

/// The `--name` words of a text.
fn named_options(text: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let b = text.as_bytes();
    let mut i = 0;
    while let Some(k) = text[i..].find("--") {
        let s = i + k;
        let before_ok = s == 0 || !(b[s - 1].is_ascii_alphanumeric() || b[s - 1] == b'-');
        let name: String = text[s + 2..]
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '-')
            .collect();
        if before_ok && name.starts_with(|c: char| c.is_ascii_lowercase()) {
            out.insert(format!("--{}", name.trim_end_matches('-')));
        }
        i = s + 2 + name.len();
    }
    out
}

fn usage_md() -> String {
    std::fs::read_to_string(root().join("docs/USAGE.md")).unwrap()
}

#[test]
fn listed_options_and_commands_are_read_from_clap_help() {
    let text = "Usage: matfit render [OPTIONS] --output <OUTPUT> <SCENE>\n\nCommands:\n  \
                rays  Primary rays\n          wrapped description\n  help  Print this\n\n\
                Options:\n  -o, --output <OUTPUT>\n          Output image\n      --spp <N>  \
                Samples (see --seed)\n  -D <NAME=VALUE>\n  -h, --help\n";
    let opts: Vec<String> = listed_options(text).into_iter().collect();
    assert_eq!(opts, ["--help", "--output", "--spp"]);
    assert_eq!(listed_commands(text), ["rays"]);
    let named: Vec<String> = named_options("`--a-b`, --c=1, x--y, -- d, `--e-`")
        .into_iter()
        .collect();
    assert_eq!(named, ["--a-b", "--c", "--e"]);
    let paths =
        named_paths("`src/a.rs`, ```sh\nrun `tests/b.rs`.\n``` `bench/out/x` `fuzz/<t>/` `x/y`");
    assert_eq!(paths, ["src/a.rs", "tests/b.rs"]);
}

#[test]
fn usage_md_names_every_command_and_option_of_the_binary_and_no_other() {
    let usage = usage_md();
    let commands = commands();
    assert!(commands.len() >= 11, "too few commands found: {commands:?}");
    let mut missing = Vec::new();
    let mut all_options = BTreeSet::new();
    for (path, options) in &commands {
        if let Some(name) = path.last() {
            if !usage.contains(&format!("`{name}`"))
                && !usage.contains(&format!("### {name}"))
                && !usage.contains(&format!("matfit {} ", path.join(" ")))
            {
                missing.push(format!("command {}", path.join(" ")));
            }
        }
        for o in options {
            if !named_options(&usage).contains(o) {
                missing.push(format!("{o} of matfit {}", path.join(" ")));
            }
        }
        all_options.extend(options.iter().cloned());
    }
    assert!(
        missing.is_empty(),
        "docs/USAGE.md does not name: {missing:?}"
    );
    for (cmd, o) in HIDDEN {
        help(&[cmd, o]); // accepted: an unknown option would fail before --help
        all_options.insert(o.to_string());
    }
    let unknown: Vec<String> = named_options(&usage)
        .into_iter()
        .filter(|o| !all_options.contains(o) && !OTHER_TOOLS.contains(&o.as_str()))
        .collect();
    assert!(
        unknown.is_empty(),
        "docs/USAGE.md names options matfit does not have: {unknown:?}"
    );
}

/// The relative links `](target)` of a Markdown file, without their `#anchor`.
fn links(text: &str) -> Vec<String> {
    text.split("](")
        .skip(1)
        .filter_map(|rest| rest.split(')').next())
        .map(|t| t.split('#').next().unwrap().to_string())
        .filter(|t| !t.is_empty() && !t.contains("://"))
        .collect()
}

/// Repository paths named in `code` (`src/scene/edit.rs`, `scenes/figure6/edits/`), leaving out
/// patterns (`<target>`, `*`) and what runs write (`out/`, `.venv`).
fn named_paths(text: &str) -> Vec<String> {
    const TOP: [&str; 9] = [
        "src/", "tests/", "bench/", "scenes/", "docs/", "fuzz/", "tools/", ".cargo/", ".ci/",
    ];
    text.replace("```", "")
        .split('`')
        .skip(1)
        .step_by(2)
        .filter(|t| TOP.iter().any(|top| t.starts_with(top)))
        .filter(|t| !t.contains(|c: char| c.is_whitespace() || "<*{$".contains(c)))
        .filter(|t| !t.contains("/out/") && !t.contains(".venv"))
        .map(|t| t.trim_end_matches(['.', ',', ':', ';']).to_string())
        .collect()
}

#[test]
fn paths_named_in_readme_and_usage_exist() {
    let mut missing = Vec::new();
    for doc in ["README.md", "docs/USAGE.md"] {
        let text = std::fs::read_to_string(root().join(doc)).unwrap();
        for p in named_paths(&text) {
            if !root().join(&p).exists() {
                missing.push(format!("{doc}: {p}"));
            }
        }
    }
    assert!(missing.is_empty(), "paths that do not exist: {missing:?}");
}

#[test]
fn links_of_readme_and_usage_lead_to_files_that_exist() {
    let mut broken = Vec::new();
    for doc in [
        "README.md",
        "docs/USAGE.md",
        "docs/DESIGN.md",
        "bench/README.md",
    ] {
        let path = root().join(doc);
        let text = std::fs::read_to_string(&path).unwrap();
        let dir = path.parent().unwrap_or(Path::new("."));
        for link in links(&text) {
            if !dir.join(&link).exists() {
                broken.push(format!("{doc}: {link}"));
            }
        }
    }
    assert!(broken.is_empty(), "broken links: {broken:?}");
}
