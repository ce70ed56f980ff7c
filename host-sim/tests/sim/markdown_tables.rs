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

/// The README is the front page (at most 200 lines); the topics live in docs/.
#[test]
fn the_readme_is_a_front_page() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let lines = std::fs::read_to_string(root.join("README.md"))
        .unwrap()
        .lines()
        .count();
    assert!(lines <= 200, "README.md has {lines} lines, at most 200");
}

/// Every relative link of the README and the docs names a file that exists.
#[test]
fn relative_links_of_readme_and_docs_resolve() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut files = vec![root.join("README.md"), root.join("CHANGELOG.md")];
    files.extend(
        std::fs::read_dir(root.join("docs"))
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|x| x == "md")),
    );
    let mut broken = Vec::new();
    for f in &files {
        let md = std::fs::read_to_string(f).unwrap();
        for (i, _) in md.match_indices("](") {
            let Some(end) = md[i + 2..].find(')') else {
                continue;
            };
            let target = &md[i + 2..i + 2 + end];
            let path = target.split('#').next().unwrap_or("");
            if path.is_empty() || path.contains("://") {
                continue;
            }
            if !f.parent().unwrap().join(path).exists() {
                broken.push(format!("{}: {target}", f.display()));
            }
        }
    }
    assert!(
        broken.is_empty(),
        "links to missing files:\n{}",
        broken.join("\n")
    );
}
