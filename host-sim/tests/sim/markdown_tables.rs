//! Every table in the README and in docs/ is valid Markdown (each `|` block parses as a table,
//! every row has the header's cells): the tables are pasted from command output and edited by
//! hand, and a broken one renders as a paragraph of pipes.

use shimmy_sim::out::html::check_tables;
use std::path::PathBuf;

#[test]
fn readme_and_docs_tables_are_valid() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut files = vec![
        root.join("README.md"),
        root.join("host-sim/scenarios/README.md"),
    ];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root.join("docs"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "md"))
        .collect();
    docs.sort();
    assert!(docs.len() >= 5, "{docs:?}");
    files.extend(docs);
    let bad: Vec<String> = files
        .iter()
        .filter_map(|f| {
            let md = std::fs::read_to_string(f).unwrap();
            check_tables(&md)
                .err()
                .map(|e| format!("{}: {e:#}", f.display()))
        })
        .collect();
    assert!(bad.is_empty(), "invalid tables:\n{}", bad.join("\n"));
}
