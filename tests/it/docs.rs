//! Docs that cannot drift silently (issue 39): the README and the manual in `docs/` against the
//! code they describe. The entity paths of recordings are checked in `cli_process.rs` (they need
//! runs) and the report's columns in `report.rs`; the rest is here.

use cellflip::cmd::cli::Cli;
use cellflip::cmd::report::docs::{BEGIN, END};
use cellflip::methods::MethodKind;
use cellflip::scene::{SceneFile, BUILT_IN};
use clap::CommandFactory;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn read(rel: &str) -> String {
    std::fs::read_to_string(root().join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

/// The backticked words of the first column of the table whose header row is `header`.
pub fn first_column(text: &str, header: &str) -> Vec<String> {
    let table = text
        .split(header)
        .nth(1)
        .unwrap_or_else(|| panic!("no table headed {header}"));
    table
        .lines()
        .skip(2)
        .take_while(|l| l.starts_with('|'))
        .flat_map(|l| {
            let first = l.split('|').nth(1).unwrap_or("");
            first
                .split('`')
                .skip(1)
                .step_by(2)
                .map(str::to_string)
                .collect::<Vec<_>>()
        })
        .collect()
}

#[test]
fn the_readme_lists_exactly_the_registered_methods() {
    let listed = first_column(&read("README.md"), "| method | what it is | reference |");
    let registered: Vec<String> = MethodKind::ALL
        .iter()
        .map(|k| k.name().to_string())
        .collect();
    assert_eq!(
        listed, registered,
        "README's method table, in registration order"
    );
    for k in MethodKind::ALL {
        let page = format!("docs/methods/{}.md", k.name());
        assert!(root().join(&page).exists(), "{page} missing");
    }
}

/// The keys serde accepts in the table `path` of a scene file, read from the error it gives for
/// an unknown key there (`expected one of ...`): every struct of the scene file rejects unknown
/// keys, so this is the parser's own list.
fn parser_keys(path: &str) -> BTreeSet<String> {
    let text = match path {
        "" => "zz_unknown = 1\n".to_string(),
        "fluid" | "solid" | "emitter" | "obstacle" => format!("[[{path}]]\nzz_unknown = 1\n"),
        _ => format!("[{path}]\nzz_unknown = 1\n"),
    };
    let err = toml::from_str::<SceneFile>(&text)
        .expect_err("an unknown key is refused")
        .to_string();
    if err.contains("there are no fields") {
        return BTreeSet::new();
    }
    let expected = err
        .split("expected ")
        .nth(1)
        .unwrap_or_else(|| panic!("{path}: {err}"));
    let list = expected.split('\n').next().unwrap();
    list.split('`')
        .skip(1)
        .step_by(2)
        .map(|k| match path {
            "" => k.to_string(),
            _ => format!("{path}.{k}"),
        })
        .collect()
}

#[test]
fn every_scene_key_is_documented_and_every_documented_key_exists() {
    let documented: BTreeSet<String> = first_column(
        &read("docs/scenes.md"),
        "| key | default | unit | used by | what |",
    )
    .into_iter()
    .collect();
    let mut tables = vec![String::new()];
    let mut parsed = BTreeSet::new();
    while let Some(t) = tables.pop() {
        for key in parser_keys(&t) {
            // A key that names a table of its own is a table when the parser asks for its keys.
            let sections = [
                "domain",
                "simulation",
                "fluid",
                "solid",
                "emitter",
                "obstacle",
            ];
            let method_table = |k: &MethodKind| key == format!("simulation.{}", k.name());
            let is_table =
                sections.contains(&key.as_str()) || MethodKind::ALL.iter().any(method_table);
            if is_table {
                tables.push(key.clone());
            }
            parsed.insert(key);
        }
    }
    assert!(parsed.len() > 60, "the parser's keys: {parsed:?}");
    let undocumented: Vec<_> = parsed.difference(&documented).collect();
    let unknown: Vec<_> = documented.difference(&parsed).collect();
    assert!(
        undocumented.is_empty(),
        "keys the parser takes that docs/scenes.md does not list: {undocumented:?}"
    );
    assert!(
        unknown.is_empty(),
        "keys docs/scenes.md lists that the parser refuses: {unknown:?}"
    );
}

#[test]
fn the_annotated_scene_file_parses() {
    let page = read("docs/scenes.md");
    let toml_block = page
        .split("```toml\n")
        .nth(1)
        .and_then(|b| b.split("```").next())
        .expect("the annotated file");
    let file: SceneFile = toml::from_str(toml_block).expect("the annotated file parses");
    assert_eq!(file.name, "tiny");
}

#[test]
fn every_built_in_scene_is_documented() {
    let page = read("docs/scenes.md");
    let listed: BTreeSet<String> = first_column(&page, "| scene | dim | what |")
        .into_iter()
        .collect();
    let built_in: BTreeSet<String> = BUILT_IN.iter().map(|(n, _)| n.to_string()).collect();
    assert_eq!(listed, built_in, "docs/scenes.md's scene table");
}

#[test]
fn every_command_and_option_is_documented() {
    let readme = read("README.md");
    let commands = first_column(&readme, "| command | what it does |");
    let cli_page = read("docs/cli.md");
    let cli = Cli::command();
    let mut names = vec![];
    for sub in cli.get_subcommands() {
        let name = sub.get_name().to_string();
        assert!(
            commands.iter().any(|c| c.split(' ').nth(1) == Some(&name)),
            "`cellflip {name}` is not in the README's command table: {commands:?}"
        );
        for arg in sub.get_arguments() {
            if let Some(long) = arg.get_long() {
                assert!(
                    cli_page.contains(&format!("--{long}")),
                    "`cellflip {name} --{long}` is not in docs/cli.md"
                );
            }
        }
        names.push(name);
    }
    assert_eq!(
        commands.len(),
        names.len(),
        "the README's command table has a command the program lacks: {commands:?}"
    );
}

/// The Markdown files of the README and the manual.
fn pages() -> Vec<PathBuf> {
    let mut out = vec![root().join("README.md"), root().join("tools/README.md")];
    let mut dirs = vec![root().join("docs")];
    while let Some(d) = dirs.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                dirs.push(p);
            } else if p.extension().is_some_and(|x| x == "md") {
                out.push(p);
            }
        }
    }
    out
}

#[test]
fn every_relative_link_in_the_docs_resolves() {
    let mut broken = vec![];
    for page in pages() {
        let text = std::fs::read_to_string(&page).unwrap();
        for target in text.split("](").skip(1).filter_map(|s| s.split(')').next()) {
            let file = target.split('#').next().unwrap();
            let external = target.contains("://") || target.starts_with("mailto:");
            if external || file.is_empty() {
                continue;
            }
            if !page.parent().unwrap().join(file).exists() {
                broken.push(format!("{}: {target}", page.display()));
            }
        }
    }
    assert!(broken.is_empty(), "links to nothing: {broken:#?}");
}

/// The first line after a generated block's start: who made it, when and how.
fn provenance(text: &str) -> &str {
    text.lines()
        .find(|l| l.starts_with("Generated "))
        .expect("a provenance line")
}

#[test]
fn the_readme_headline_comes_from_the_results_page() {
    let readme = read("README.md");
    let block = readme
        .split(BEGIN)
        .nth(1)
        .and_then(|b| b.split(END).next())
        .expect("the README's generated block");
    let page = read("docs/results.md");
    assert_eq!(
        provenance(block),
        provenance(&page),
        "README's headline and docs/results.md come from different runs of `cellflip report --docs`"
    );
    assert!(provenance(&page).contains("by `cellflip report --docs"));
    for k in MethodKind::ALL {
        assert!(
            block.contains(&format!("| `{}` |", k.name())),
            "{} has no headline row",
            k.name()
        );
    }
}
