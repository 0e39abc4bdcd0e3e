//! The top-level modules of `hilcontact-core` and `hilcontact-rt` import each other without a
//! circle: the graph of `crate::<module>` references between the files of each crate's
//! `src/` (a module's submodules count as the module) has no cycle.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// Module name -> the crate modules its files refer to (`crate::name`).
fn module_graph(src: &Path) -> BTreeMap<String, BTreeSet<String>> {
    // every file under src/, folders of folders included (e.g. crates/rt/src/devices/egm/)
    let mut files = Vec::new();
    let mut folders = vec![src.to_path_buf()];
    while let Some(folder) = folders.pop() {
        for entry in std::fs::read_dir(&folder).expect("module dir") {
            let path = entry.expect("entry").path();
            if path.is_dir() {
                folders.push(path);
            } else {
                files.push(path);
            }
        }
    }
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for file in files
        .iter()
        .filter(|p| p.extension().is_some_and(|e| e == "rs"))
    {
        let relative = file.strip_prefix(src).expect("under src");
        let module = relative
            .components()
            .next()
            .and_then(|c| c.as_os_str().to_str())
            .map(|s| s.trim_end_matches(".rs").to_string())
            .expect("module name");
        if module == "lib" {
            continue; // the crate root declares and re-exports every module
        }
        let text = std::fs::read_to_string(file).expect("read");
        let code: String = text
            .lines()
            .filter(|l| !l.trim_start().starts_with("//"))
            .collect::<Vec<_>>()
            .join("\n");
        let targets = graph.entry(module.clone()).or_default();
        for (i, _) in code.match_indices("crate::") {
            let before = code[..i].chars().last();
            if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
                continue; // `hilcontact_core::` and the like
            }
            let name: String = code[i + 7..]
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            if !name.is_empty() && name != module {
                targets.insert(name);
            }
        }
    }
    graph
}

/// A cycle of the graph, if any (depth-first search).
fn find_cycle(graph: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        node: &str,
        graph: &BTreeMap<String, BTreeSet<String>>,
        path: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(at) = path.iter().position(|n| n == node) {
            let mut cycle = path[at..].to_vec();
            cycle.push(node.to_string());
            return Some(cycle);
        }
        if done.contains(node) {
            return None;
        }
        path.push(node.to_string());
        for next in graph.get(node).into_iter().flatten() {
            if let Some(c) = visit(next, graph, path, done) {
                return Some(c);
            }
        }
        path.pop();
        done.insert(node.to_string());
        None
    }
    let mut done = BTreeSet::new();
    graph
        .keys()
        .find_map(|n| visit(n, graph, &mut Vec::new(), &mut done))
}

fn assert_acyclic(crate_dir: &str) {
    let src = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join(crate_dir)
        .join("src");
    let graph = module_graph(&src);
    assert!(
        graph.len() > 5,
        "read too few modules of {crate_dir}: {graph:?}"
    );
    if let Some(cycle) = find_cycle(&graph) {
        panic!("circular imports in {crate_dir}: {}", cycle.join(" -> "));
    }
}

#[test]
fn core_modules_import_without_a_circle() {
    assert_acyclic(".");
}

#[test]
fn rt_modules_import_without_a_circle() {
    assert_acyclic("../rt");
}

/// Each device folder of the real-time crate (`crates/rt/src/devices/<kind>/`) names no other
/// device: what devices share lives beside them (`devices/link.rs`, `transport.rs`,
/// `pose.rs`), and a device is added or removed with its folder and its registry line.
#[test]
fn rt_device_folders_name_no_other_device() {
    let devices = Path::new(env!("CARGO_MANIFEST_DIR")).join("../rt/src/devices");
    let kinds: Vec<String> = std::fs::read_dir(&devices)
        .expect("devices")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.is_dir())
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    assert!(kinds.len() >= 4, "{kinds:?}");
    for kind in &kinds {
        for entry in std::fs::read_dir(devices.join(kind)).expect("device folder") {
            let file = entry.expect("entry").path();
            let text = std::fs::read_to_string(&file).expect("read");
            for other in kinds.iter().filter(|k| *k != kind) {
                let code = text
                    .lines()
                    .filter(|l| !l.trim_start().starts_with("//"))
                    .any(|l| l.contains(&format!("devices::{other}")));
                assert!(!code, "{} names the device {other}", file.display());
            }
        }
    }
}

#[test]
fn a_circle_is_found() {
    let mut graph = BTreeMap::new();
    graph.insert("a".to_string(), BTreeSet::from(["b".to_string()]));
    graph.insert("b".to_string(), BTreeSet::from(["c".to_string()]));
    graph.insert("c".to_string(), BTreeSet::from(["a".to_string()]));
    assert_eq!(find_cycle(&graph).map(|c| c.len()), Some(4));
    if let Some(t) = graph.get_mut("c") {
        t.clear();
    }
    assert_eq!(find_cycle(&graph), None);
}
