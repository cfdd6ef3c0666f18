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
