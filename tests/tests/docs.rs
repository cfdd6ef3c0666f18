//! Code shown in the docs is the code that runs: the pandas snippet of docs/traces.md is the
//! body of `tests/python/fig3.py` (which CI runs on a short run's CSV export).

use std::path::Path;

fn read(rel: &str) -> String {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(rel);
    std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

#[test]
fn the_fig3_snippet_of_docs_traces_is_the_script_ci_runs() {
    let doc = read("docs/traces.md");
    let section = doc
        .split("### The paper's Fig. 3 from the CSV alone")
        .nth(1)
        .expect("docs/traces.md has the Fig. 3 section");
    let snippet = section
        .split("```python\n")
        .nth(1)
        .and_then(|s| s.split("```").next())
        .expect("a python block in the Fig. 3 section");
    let script = read("tests/python/fig3.py");
    let first = snippet.lines().next().expect("a non-empty snippet");
    let body: Vec<&str> = script
        .lines()
        .skip_while(|l| *l != first)
        .take(snippet.lines().count())
        .collect();
    assert_eq!(
        body,
        snippet.lines().collect::<Vec<_>>(),
        "the snippet of docs/traces.md differs from tests/python/fig3.py"
    );
}

/// The repository's text files (sources, docs, scenarios, examples, scripts), relative paths;
/// build outputs and version control left out.
fn text_files() -> Vec<std::path::PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut out = Vec::new();
    let mut todo = vec![root.clone()];
    while let Some(dir) = todo.pop() {
        let entries = std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
        for entry in entries {
            let path = entry.expect("a directory entry").path();
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
            if path.is_dir() {
                if !name.starts_with('.') && name != "target" && name != "__pycache__" {
                    todo.push(path);
                }
            } else if ["rs", "md", "toml", "py", "json", "yaml", "sh"]
                .iter()
                .any(|ext| name.ends_with(&format!(".{ext}")))
            {
                out.push(
                    path.strip_prefix(&root)
                        .expect("below the root")
                        .to_path_buf(),
                );
            }
        }
    }
    out.sort();
    out
}

/// The headings of a Markdown file, without their `#`s (code blocks left out).
fn headings(doc: &str) -> Vec<&str> {
    let mut in_code = false;
    doc.lines()
        .filter(|l| {
            if l.starts_with("```") {
                in_code = !in_code;
            }
            !in_code
        })
        .filter_map(|l| l.strip_prefix('#'))
        .map(|l| l.trim_start_matches('#').trim())
        .collect()
}

/// What the project prints and documents cites its own docs: `docs/x.md, "Heading"` names a
/// heading of that file (the heading itself or its start, up to a word's end), and nothing points to a file
/// the repository does not have (the specification the project was built from is not in it).
#[test]
fn every_section_cited_as_docs_file_and_heading_exists_and_nothing_cites_a_missing_spec() {
    let mut cited = 0;
    let mut problems = Vec::new();
    // This file names what it looks for.
    let me = Path::new("tests/tests/docs.rs");
    for rel in text_files().into_iter().filter(|f| f != me) {
        let text = read(&rel.to_string_lossy());
        for (n, line) in text.lines().enumerate() {
            let at = format!("{}:{}", rel.display(), n + 1);
            if ["SPEC §", "of SPEC", "SPEC's", "SPEC section"]
                .iter()
                .any(|s| line.contains(s))
            {
                problems.push(format!("{at}: cites SPEC, which is not in the repository"));
            }
            let mut rest = line;
            while let Some(i) = rest.find("docs/") {
                rest = &rest[i + "docs/".len()..];
                let Some(end) = rest.find(".md") else { break };
                let file = &rest[..end];
                if !file.chars().all(|c| c.is_ascii_lowercase() || c == '-') {
                    continue;
                }
                let after = &rest[end + ".md".len()..];
                let Some(quoted) = after.strip_prefix(", \"").or(after.strip_prefix(", \\\""))
                else {
                    continue;
                };
                let Some(heading) = quoted.split(['"', '\\']).next() else {
                    continue;
                };
                let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../docs/{file}.md"));
                let Ok(doc) = std::fs::read_to_string(&path) else {
                    problems.push(format!("{at}: cites docs/{file}.md, which is not there"));
                    continue;
                };
                let found = headings(&doc).iter().any(|h| {
                    h.strip_prefix(heading)
                        .is_some_and(|tail| !tail.starts_with(char::is_alphanumeric))
                });
                cited += 1;
                if !found {
                    problems.push(format!("{at}: docs/{file}.md has no heading \"{heading}\""));
                }
            }
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
    // The citations this checks are there (a parser that finds none checks nothing).
    assert!(
        cited >= 20,
        "only {cited} citations of a docs heading found"
    );
}
