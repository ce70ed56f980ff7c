//! The module graph of the library crates, read from their sources with `syn`:
//!
//! - no file imports a file that imports it back, directly or through others (the file graph
//!   of `core`, `host-sim` and `firmware` has no cycle);
//! - host-sim's layers are used only downwards (`model` < `sim` < `out` < `cmd`), and no
//!   command imports another command;
//! - core's layers are used only downwards (`model` < `control` < `estimation` < `supervision`
//!   < `vehicle`);
//! - a concrete vehicle model is named in few files outside its own: its core folder, its plant
//!   file and the model registry (`host-sim/src/model/registry.rs`) are where it lives; every
//!   other file of the simulator and the Python bindings reaches it through the registry
//!   ([`each_model_is_named_in_few_files_outside_its_own`]).
//!
//! File X imports file Y when X names a path (in a `use`, a type, an expression, a pattern)
//! that resolves into Y's module: `crate::a::b::Item`, `super::...`, `self::child::...`, or a
//! bare `child::...` of a child module X declares. A `mod child;` declaration alone is not an
//! import, a `pub use child::Item` re-export is. Doc comments and strings are not code and do
//! not count. An inline `mod tests { use super::*; }` stays inside its file.
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use syn::visit::Visit;

type ModPath = Vec<String>;

/// One library crate's source files by module path (`[]` is `lib.rs`).
struct Crate {
    name: &'static str,
    files: BTreeMap<ModPath, PathBuf>,
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ sits in the workspace root")
        .to_path_buf()
}

/// Every module file reachable by the directory convention from `src/lib.rs` (binaries,
/// `main.rs` and `bin/` are crate roots of their own and left out).
fn load(name: &'static str, dir: &str) -> Crate {
    load_src(name, &root().join(dir).join("src"))
}

/// [`load`] for the source folder `src`.
fn load_src(name: &'static str, src: &Path) -> Crate {
    let src = src.to_path_buf();
    let mut files = BTreeMap::new();
    let mut stack = vec![src.clone()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            let rel = p.strip_prefix(&src).unwrap().to_path_buf();
            if p.is_dir() {
                if rel != Path::new("bin") {
                    stack.push(p);
                }
                continue;
            }
            if p.extension().is_none_or(|x| x != "rs") || rel == Path::new("main.rs") {
                continue;
            }
            let mut m: ModPath = rel
                .with_extension("")
                .components()
                .map(|c| c.as_os_str().to_string_lossy().into_owned())
                .collect();
            if m.last().is_some_and(|l| l == "mod" || l == "lib") {
                m.pop();
            }
            files.insert(m, p);
        }
    }
    Crate { name, files }
}

/// Collects the module paths a file names, resolved to absolute module paths.
struct Imports<'a> {
    /// Module path of the file.
    file: &'a [String],
    /// Inline modules entered inside the file (`mod tests { ... }`).
    inline: Vec<String>,
    /// Child modules declared by the file as `mod x;` (a bare `x::...` path means them).
    children: BTreeSet<String>,
    found: BTreeSet<ModPath>,
}

impl Imports<'_> {
    fn scope(&self) -> ModPath {
        let mut s = self.file.to_vec();
        s.extend(self.inline.iter().cloned());
        s
    }

    /// Resolves a path's leading segments; `None` for paths into other crates or local names.
    fn resolve(&self, segs: &[String]) -> Option<ModPath> {
        let first = segs.first()?;
        let mut base = self.scope();
        let mut rest = segs;
        match first.as_str() {
            "crate" => {
                base.clear();
                rest = &segs[1..];
            }
            "self" => rest = &segs[1..],
            "super" => {
                while rest.first().is_some_and(|s| s == "super") {
                    base.pop()?;
                    rest = &rest[1..];
                }
            }
            s if self.inline.is_empty() && self.children.contains(s) && segs.len() > 1 => {}
            _ => return None,
        }
        base.extend(rest.iter().cloned());
        Some(base)
    }

    fn record(&mut self, segs: &[String]) {
        if let Some(p) = self.resolve(segs) {
            self.found.insert(p);
        }
    }
}

fn use_paths(tree: &syn::UseTree, prefix: &mut Vec<String>, out: &mut Vec<Vec<String>>) {
    match tree {
        syn::UseTree::Path(p) => {
            prefix.push(p.ident.to_string());
            use_paths(&p.tree, prefix, out);
            prefix.pop();
        }
        syn::UseTree::Name(n) => {
            let mut v = prefix.clone();
            if n.ident != "self" {
                v.push(n.ident.to_string());
            }
            out.push(v);
        }
        syn::UseTree::Rename(r) => {
            let mut v = prefix.clone();
            v.push(r.ident.to_string());
            out.push(v);
        }
        syn::UseTree::Glob(_) => out.push(prefix.clone()),
        syn::UseTree::Group(g) => g.items.iter().for_each(|t| use_paths(t, prefix, out)),
    }
}

impl<'ast> Visit<'ast> for Imports<'_> {
    fn visit_item_mod(&mut self, m: &'ast syn::ItemMod) {
        if let Some((_, items)) = &m.content {
            self.inline.push(m.ident.to_string());
            items.iter().for_each(|i| self.visit_item(i));
            self.inline.pop();
        }
    }

    fn visit_item_use(&mut self, u: &'ast syn::ItemUse) {
        let mut paths = Vec::new();
        use_paths(&u.tree, &mut Vec::new(), &mut paths);
        paths.iter().for_each(|p| self.record(p));
    }

    fn visit_path(&mut self, p: &'ast syn::Path) {
        let segs: Vec<String> = p.segments.iter().map(|s| s.ident.to_string()).collect();
        self.record(&segs);
        syn::visit::visit_path(self, p);
    }

    fn visit_macro(&mut self, m: &'ast syn::Macro) {
        // Paths inside macro calls (`format!("{}", crate::x::y())`) are code too.
        if let Ok(e) = m.parse_body_with(
            syn::punctuated::Punctuated::<syn::Expr, syn::Token![,]>::parse_terminated,
        ) {
            e.iter().for_each(|x| self.visit_expr(x));
        }
        syn::visit::visit_macro(self, m);
    }
}

/// The file a module path lives in: its longest prefix that is a file of the crate.
fn owner<'a>(c: &'a Crate, p: &[String]) -> Option<&'a ModPath> {
    (0..=p.len())
        .rev()
        .find_map(|n| c.files.get_key_value(&p[..n]).map(|(k, _)| k))
}

/// File-level import graph: module path -> module paths of the files it imports.
fn graph(c: &Crate) -> BTreeMap<ModPath, BTreeSet<ModPath>> {
    let mut g = BTreeMap::new();
    for (m, path) in &c.files {
        let text = std::fs::read_to_string(path).unwrap();
        let ast = syn::parse_file(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let children = ast
            .items
            .iter()
            .filter_map(|i| match i {
                syn::Item::Mod(m) if m.content.is_none() => Some(m.ident.to_string()),
                _ => None,
            })
            .collect();
        let mut v = Imports {
            file: m,
            inline: Vec::new(),
            children,
            found: BTreeSet::new(),
        };
        v.visit_file(&ast);
        let deps = v
            .found
            .iter()
            .filter_map(|p| owner(c, p))
            .filter(|o| *o != m)
            .cloned()
            .collect();
        g.insert(m.clone(), deps);
    }
    g
}

fn show(c: &Crate, m: &ModPath) -> String {
    let f = &c.files[m];
    f.strip_prefix(root()).unwrap_or(f).display().to_string()
}

/// Every cycle's files, as strongly connected components of more than one file.
fn cycles(c: &Crate, g: &BTreeMap<ModPath, BTreeSet<ModPath>>) -> Vec<Vec<String>> {
    // Reachability by depth-first search from every node: small graphs, clarity over speed.
    let reach = |from: &ModPath| {
        let mut seen = BTreeSet::new();
        let mut stack = vec![from.clone()];
        while let Some(n) = stack.pop() {
            for d in &g[&n] {
                if seen.insert(d.clone()) {
                    stack.push(d.clone());
                }
            }
        }
        seen
    };
    let reachable: BTreeMap<&ModPath, BTreeSet<ModPath>> =
        g.keys().map(|k| (k, reach(k))).collect();
    let mut done = BTreeSet::new();
    let mut out = Vec::new();
    for a in g.keys() {
        if done.contains(a) || !reachable[a].contains(a) {
            continue;
        }
        let comp: Vec<&ModPath> = g
            .keys()
            .filter(|b| reachable[a].contains(*b) && reachable[*b].contains(a))
            .collect();
        comp.iter().for_each(|b| {
            done.insert((*b).clone());
        });
        let mut names: Vec<String> = comp.iter().map(|b| show(c, b)).collect();
        names.sort();
        // Name one edge pair per component so the message says where to look.
        let edges: Vec<String> = comp
            .iter()
            .flat_map(|b| {
                g[*b]
                    .iter()
                    .filter(|d| comp.contains(d))
                    .map(move |d| (b, d))
            })
            .map(|(b, d)| format!("{} -> {}", show(c, b), show(c, d)))
            .collect();
        names.push(format!("edges: {}", edges.join(", ")));
        out.push(names);
    }
    out
}

fn crates() -> Vec<Crate> {
    vec![
        load("shimmy-core", "core"),
        load("shimmy-sim", "host-sim"),
        load("shimmy-firmware", "firmware"),
    ]
}

#[test]
fn no_file_imports_a_file_that_imports_it_back() {
    let mut bad = Vec::new();
    for c in crates() {
        let g = graph(&c);
        for cyc in cycles(&c, &g) {
            bad.push(format!("{}: {}", c.name, cyc.join(" <-> ")));
        }
    }
    assert!(bad.is_empty(), "import cycles:\n{}", bad.join("\n"));
}

/// A scratch crate in a fresh temporary folder from (path under `src/`, text) pairs; the
/// folder is returned for removal.
fn scratch(tag: &str, sources: &[(&str, &str)]) -> (Crate, PathBuf) {
    let dir = std::env::temp_dir().join(format!("shimmy-arch-{tag}-{}", std::process::id()));
    let src = dir.join("src");
    for (path, text) in sources {
        let f = src.join(path);
        std::fs::create_dir_all(f.parent().unwrap()).unwrap();
        std::fs::write(f, text).unwrap();
    }
    (load_src("scratch", &src), dir)
}

/// The checker itself must see a cycle where there is one (else the test above proves
/// nothing): two files of a scratch crate that name each other, one through `use`, one
/// through a path in an expression; a third file importing its sibling only is no cycle.
#[test]
fn the_checker_finds_a_planted_cycle() {
    let (scratch, dir) = scratch(
        "cycle",
        &[
            ("lib.rs", "pub mod a;\npub mod c;\n"),
            ("a/mod.rs", "pub mod b;\npub use b::B;\npub struct A;\n"),
            (
                "a/b.rs",
                "/// [`crate::c`] in a doc is no import.\npub struct B;\npub fn f() -> usize { core::mem::size_of::<super::A>() }\n",
            ),
            ("c.rs", "use crate::a::b::B;\npub fn g(_: B) {}\n"),
        ],
    );
    let g = graph(&scratch);
    let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<ModPath>();
    assert_eq!(g[&s(&["c"])], BTreeSet::from([s(&["a", "b"])]));
    assert_eq!(g[&s(&[])], BTreeSet::new(), "`pub mod` alone is no import");
    let found: Vec<Vec<String>> = cycles(&scratch, &g)
        .into_iter()
        .map(|mut c| {
            c.pop();
            c
        })
        .collect();
    std::fs::remove_dir_all(&dir).ok();
    assert_eq!(found.len(), 1, "{found:?}");
    assert_eq!(found[0].len(), 2);
    assert!(found[0][0].ends_with("a/b.rs") && found[0][1].ends_with("a/mod.rs"));
}

/// The files of `c` that sit in no layer (`layer`; the crate root, the map, aside) or import a
/// file of a higher layer (`names`: the layers' names, lowest first), and what `other` finds
/// wrong with an import of the same or a lower layer, or of a file in no layer.
fn layered_violations(
    c: &Crate,
    names: &[&str],
    layer: impl Fn(&ModPath) -> Option<usize>,
    other: impl Fn(&ModPath, usize, &ModPath, Option<usize>) -> Option<String>,
) -> Vec<String> {
    let mut bad = Vec::new();
    for (m, deps) in graph(c) {
        let Some(lm) = layer(&m) else {
            if !m.is_empty() {
                bad.push(format!("{} is in no layer", show(c, &m)));
            }
            continue;
        };
        for d in &deps {
            match layer(d) {
                Some(ld) if ld > lm => bad.push(format!(
                    "{} ({}) uses the higher layer {} ({})",
                    show(c, &m),
                    names[lm],
                    show(c, d),
                    names[ld]
                )),
                ld => bad.extend(other(&m, lm, d, ld)),
            }
        }
    }
    bad
}

/// The concern of a file of host-sim's `sim` layer, lowest first: what the user hands in
/// (`input`) < running the model (`run`) < what runs it for a purpose (`device`, `study`,
/// `analyze`: siblings, none uses another).
fn sim_concern(m: &ModPath) -> Option<(usize, &str)> {
    let c = m.get(1)?.as_str();
    let rank = match c {
        "input" => 0,
        "run" => 1,
        "device" | "study" | "analyze" => 2,
        _ => return None,
    };
    Some((rank, c))
}

/// host-sim's rule: a file uses only its own or lower layers (`model` < `sim` < `out` <
/// `cmd`), inside `sim` only its own or lower concerns ([`sim_concern`]), no command uses
/// another command, and only the crate root sits outside the layers.
fn layer_violations(c: &Crate) -> Vec<String> {
    const LAYERS: [&str; 4] = ["model", "sim", "out", "cmd"];
    let layer = |m: &ModPath| m.first().and_then(|t| LAYERS.iter().position(|l| l == t));
    let mut bad = layered_violations(c, &LAYERS, layer, |m, lm, d, ld| match ld {
        Some(1) if lm == 1 => match (sim_concern(m), sim_concern(d)) {
            (Some((rm, cm)), Some((rd, cd))) if rd > rm || (rd == rm && rm == 2 && cm != cd) => {
                Some(format!(
                    "sim/{cm} ({}) uses sim/{cd} ({})",
                    show(c, m),
                    show(c, d)
                ))
            }
            _ => None,
        },
        // Two different commands: cmd/<a>... and cmd/<b>...
        Some(3) if lm == 3 && m.get(1) != d.get(1) && m.len() > 1 && d.len() > 1 => Some(format!(
            "command {} imports command {}",
            show(c, m),
            show(c, d)
        )),
        None => Some(format!("{} uses the crate root", show(c, m))),
        _ => None,
    });
    let no_concern = graph(c).into_keys().filter(|m| {
        m.first().is_some_and(|t| t == "sim") && m.len() > 1 && sim_concern(m).is_none()
    });
    bad.extend(no_concern.map(|m| format!("{} is in no concern of sim", show(c, &m))));
    bad
}

#[test]
fn host_sim_layers_are_used_downwards_and_commands_stand_alone() {
    let bad = layer_violations(&load("shimmy-sim", "host-sim"));
    assert!(bad.is_empty(), "layer violations:\n{}", bad.join("\n"));
}

/// The layer of a module of `shimmy-core` (`docs/architecture.md`, "Layers"): model <
/// control < estimation < supervision (the safe controller schedules the damper on the
/// estimator's margin report and hands the estimator its validated samples) < vehicle. A
/// model's board record (`vehicles/<model>/board.rs`: its vehicle as the firmware stores it) is
/// vehicle-level configuration above the model; a file of tests (`.../tests.rs`) sits at the
/// top, so it may use any layer; `lib.rs` is the crate's map.
fn core_layer(m: &ModPath) -> Option<usize> {
    const MODEL: [&str; 10] = [
        "fmt",
        "eigen",
        "float",
        "model",
        "mr_damper",
        "sqrt",
        "stability",
        "trig",
        "units",
        "vehicles",
    ];
    let first = m.first()?.as_str();
    let top = Some(4);
    if m.last().is_some_and(|l| l == "tests")
        || (first == "vehicles" && m.get(2).is_some_and(|f| f == "board"))
    {
        return top;
    }
    if MODEL.contains(&first) {
        return Some(0);
    }
    ["control", "estimator", "supervisor", "vehicle"]
        .iter()
        .position(|l| *l == first)
        .map(|i| i + 1)
}

/// core's rule: a file uses only its own or lower layers.
fn core_layer_violations(c: &Crate) -> Vec<String> {
    const NAMES: [&str; 5] = ["model", "control", "estimation", "supervision", "vehicle"];
    layered_violations(c, &NAMES, core_layer, |m, _, d, ld| {
        (ld.is_none() && !d.is_empty()).then(|| format!("{} uses {}", show(c, m), show(c, d)))
    })
}

#[test]
fn core_layers_are_used_downwards() {
    let bad = core_layer_violations(&load("shimmy-core", "core"));
    assert!(
        bad.is_empty(),
        "layer violations in core:\n{}",
        bad.join("\n")
    );
}

/// The core layer check sees a model file using the estimator and a file outside the layers,
/// and lets a file of tests and a board record use the layers above the model.
#[test]
fn the_core_layer_check_finds_planted_violations() {
    let (c, dir) = scratch(
        "core-layers",
        &[
            (
                "lib.rs",
                "pub mod estimator;\npub mod vehicles;\npub mod vehicle;\npub mod extra;\n",
            ),
            ("estimator/mod.rs", "pub fn m() {}\n"),
            ("vehicle.rs", "pub fn v() {}\n"),
            ("extra.rs", "pub fn e() {}\n"),
            ("vehicles/mod.rs", "pub mod car;\n"),
            (
                "vehicles/car/mod.rs",
                "pub mod board;\nmod tests;\npub fn f() { crate::estimator::m(); }\n",
            ),
            (
                "vehicles/car/board.rs",
                "pub fn b() { crate::vehicle::v(); }\n",
            ),
            ("vehicles/car/tests.rs", "fn t() { crate::vehicle::v(); }\n"),
        ],
    );
    let bad = core_layer_violations(&c);
    std::fs::remove_dir_all(&dir).ok();
    assert_eq!(bad.len(), 2, "{bad:#?}");
    assert!(bad.iter().any(|b| b.contains("extra.rs is in no layer")));
    assert!(bad.iter().any(
        |b| b.contains("car/mod.rs (model) uses the higher layer") && b.contains("estimation")
    ));
}

/// The layer check must see each kind of violation (else the test above proves nothing): a
/// model file using a command, one command using another, a file outside the layers, a `sim`
/// concern using a higher or a sibling one, a `sim` file in no concern; a command using a model
/// file and its own sibling file, a concern using a lower one, are fine.
#[test]
fn the_layer_check_finds_planted_violations() {
    let (c, dir) = scratch(
        "layers",
        &[
            (
                "lib.rs",
                "pub mod cmd;\npub mod model;\npub mod extra;\npub mod sim;\n",
            ),
            ("model/mod.rs", "pub mod plant;\n"),
            ("model/plant.rs", "pub fn f() { crate::cmd::a::run(); }\n"),
            ("cmd/mod.rs", "pub mod a;\npub mod b;\n"),
            ("cmd/a/mod.rs", "pub mod args;\npub fn run() {}\n"),
            (
                "cmd/a/args.rs",
                "pub fn g() { crate::model::plant::f(); }\n",
            ),
            ("cmd/b.rs", "pub fn h() { crate::cmd::a::args::g(); }\n"),
            ("extra.rs", "pub fn e() {}\n"),
            (
                "sim/mod.rs",
                "pub mod input;\npub mod run;\npub mod device;\npub mod study;\npub mod misc;\n",
            ),
            (
                "sim/input/files.rs",
                "pub fn r() { crate::sim::run::go(); }\n",
            ),
            ("sim/input/mod.rs", "pub mod files;\n"),
            (
                "sim/run.rs",
                "pub fn go() { crate::sim::input::files::r(); }\n",
            ),
            ("sim/device.rs", "pub fn d() { crate::sim::study::s(); }\n"),
            ("sim/study.rs", "pub fn s() { crate::sim::run::go(); }\n"),
            ("sim/misc.rs", "pub fn m() { crate::model::plant::f(); }\n"),
        ],
    );
    let bad = layer_violations(&c);
    std::fs::remove_dir_all(&dir).ok();
    assert_eq!(bad.len(), 6, "{bad:#?}");
    let found = |a: &str, b: &str| bad.iter().any(|x| x.contains(a) && x.contains(b));
    assert!(found("cmd/b.rs", "imports command"));
    assert!(found("extra.rs", "is in no layer"));
    assert!(found("model/plant.rs (model)", "uses the higher layer"));
    assert!(
        found("sim/input (", "uses sim/run"),
        "a lower concern using a higher one"
    );
    assert!(
        found("sim/device (", "uses sim/study"),
        "one sibling concern using another"
    );
    assert!(found("sim/misc.rs", "no concern of sim"));
}

/// A concrete vehicle model as the sources name it: its types and constants, the paths of its
/// modules (`vehicles::truck`, `truck_plant`) and its variants of the model enums
/// (`ModelVehicle::Truck`, `AnyScenario::Truck`); and the files where it lives (its plant file;
/// its core folder and the registry are outside the count for every model).
struct NamedModel {
    name: &'static str,
    idents: &'static [&'static str],
    /// `a::b` pairs of path segments.
    pairs: &'static [(&'static str, &'static str)],
    home: &'static [&'static str],
}

const NAMED_MODELS: [NamedModel; 5] = [
    NamedModel {
        name: "car-4dof",
        idents: &["PlantParams", "ParamSet"],
        pairs: &[
            ("vehicles", "car"),
            ("ModelVehicle", "Car"),
            ("AnyScenario", "Car"),
        ],
        home: &[
            "host-sim/src/model/plant.rs",
            "host-sim/src/model/car_plant.rs",
        ],
    },
    NamedModel {
        name: "mining-truck-5dof",
        idents: &[
            "TruckParams",
            "TruckSet",
            "TruckPlant",
            "TruckVehicle",
            "TRUCK_FIELDS",
            "truck_plant",
        ],
        pairs: &[
            ("vehicles", "truck"),
            ("ModelVehicle", "Truck"),
            ("AnyScenario", "Truck"),
        ],
        home: &["host-sim/src/model/truck_plant.rs"],
    },
    NamedModel {
        name: "dual-axle-truck-8dof",
        idents: &[
            "DualAxleParams",
            "DualAxleSet",
            "DualAxlePlant",
            "DUAL_AXLE_FIELDS",
            "dual_axle_plant",
        ],
        pairs: &[
            ("vehicles", "dual_axle"),
            ("ModelVehicle", "DualAxle"),
            ("AnyScenario", "DualAxle"),
        ],
        home: &["host-sim/src/model/dual_axle_plant.rs"],
    },
    NamedModel {
        name: "trailer-2dof",
        idents: &[
            "TrailerParams",
            "TrailerSet",
            "TrailerPlant",
            "TRAILER_FIELDS",
            "trailer_plant",
        ],
        pairs: &[
            ("vehicles", "trailer"),
            ("ModelVehicle", "Trailer"),
            ("AnyScenario", "Trailer"),
        ],
        home: &["host-sim/src/model/trailer_plant.rs"],
    },
    NamedModel {
        name: "towed-wheel-string",
        idents: &[
            "TowedWheelParams",
            "TowedWheelSet",
            "TowedWheelPlant",
            "TOWED_WHEEL_FIELDS",
            "towed_wheel_plant",
        ],
        pairs: &[
            ("vehicles", "towed_wheel"),
            ("ModelVehicle", "TowedWheel"),
            ("AnyScenario", "TowedWheel"),
        ],
        home: &["host-sim/src/model/towed_wheel_plant.rs"],
    },
];

/// The registry: the one file that names every model.
const REGISTRY: &str = "host-sim/src/model/registry.rs";

/// The source folders counted: the simulator's library and binary, the Python bindings.
const COUNTED: [&str; 2] = ["host-sim/src", "python/src"];

/// The most files outside its own (and the registry) that may name a model: 3 (issue 48). What
/// names one is its own command and study (`gas-charge` and `truck_study`, `bifurcation` and
/// `dual_axle_study`, `sway-damping` and `trailer_study`; the car's parameter list in
/// `sensitivity`, its benchmark against the SciPy reference and the Python `plant()`).
/// Everything else reaches a model through the registry: `BoardModel` for what a firmware image
/// needs, `ReferenceModel` for the default of the generic simulator types.
const MAX_FILES: [(&str, usize); 5] = [
    ("car-4dof", 3),
    ("mining-truck-5dof", 3),
    ("dual-axle-truck-8dof", 3),
    ("trailer-2dof", 3),
    ("towed-wheel-string", 3),
];

/// Every identifier of `ts` and every `a::b` pair of consecutive path segments (macro
/// arguments included; comments and strings are not tokens that count), leaving out
/// `#[cfg(test)]` modules (a model's tests name it) and the names of `mod` declarations (the
/// plant file's `mod` line is part of adding it).
fn names(
    ts: proc_macro2::TokenStream,
    idents: &mut BTreeSet<String>,
    pairs: &mut BTreeSet<(String, String)>,
) {
    use proc_macro2::TokenTree;
    let toks: Vec<TokenTree> = ts.into_iter().collect();
    let mut skip_to_brace = false;
    let mut skip_ident = false;
    for (i, t) in toks.iter().enumerate() {
        // `#[cfg(test)] mod tests { ... }`: a model's tests name it, they dispatch nothing
        if let (TokenTree::Punct(p), Some(TokenTree::Group(g))) = (t, toks.get(i + 1)) {
            if p.as_char() == '#' && g.stream().to_string().replace(' ', "") == "cfg(test)" {
                skip_to_brace = true;
            }
        }
        if skip_to_brace {
            // the item ends at its body or at `;` (`#[cfg(test)] use ...;`)
            match t {
                TokenTree::Group(g) => {
                    skip_to_brace = g.delimiter() != proc_macro2::Delimiter::Brace
                }
                TokenTree::Punct(p) => skip_to_brace = p.as_char() != ';',
                _ => {}
            }
            continue;
        }
        // `mod truck_plant;`: declaring the plant file is adding it
        if skip_ident {
            skip_ident = false;
            if matches!(t, TokenTree::Ident(_)) {
                continue;
            }
        }
        match t {
            TokenTree::Group(g) => names(g.stream(), idents, pairs),
            TokenTree::Ident(a) if a == "mod" => skip_ident = true,
            TokenTree::Ident(a) => {
                idents.insert(a.to_string());
                if let [TokenTree::Punct(p), TokenTree::Punct(q), TokenTree::Ident(b), ..] =
                    &toks[i + 1..]
                {
                    if p.as_char() == ':' && q.as_char() == ':' {
                        pairs.insert((a.to_string(), b.to_string()));
                    }
                }
                // `a::{b, c}`
                if let [TokenTree::Punct(p), TokenTree::Punct(q), TokenTree::Group(g), ..] =
                    &toks[i + 1..]
                {
                    if p.as_char() == ':' && q.as_char() == ':' {
                        for b in g.stream() {
                            if let TokenTree::Ident(b) = b {
                                pairs.insert((a.to_string(), b.to_string()));
                            }
                        }
                    }
                }
            }
            _ => {}
        }
    }
}

/// The `.rs` files under `dir`, relative to the workspace root.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// For each model, the counted files outside its own and the registry that name it.
/// The sources are the workspace's, or those under `SHIMMY_MODEL_COUNT_ROOT` (another checkout,
/// to compare counts).
fn files_naming_each_model() -> BTreeMap<&'static str, Vec<String>> {
    let root = std::env::var_os("SHIMMY_MODEL_COUNT_ROOT").map_or_else(root, PathBuf::from);
    let mut files = Vec::new();
    for d in COUNTED {
        rust_files(&root.join(d), &mut files);
    }
    files.sort();
    let mut out: BTreeMap<&'static str, Vec<String>> =
        NAMED_MODELS.iter().map(|m| (m.name, Vec::new())).collect();
    for f in files {
        let rel = f
            .strip_prefix(&root)
            .unwrap()
            .to_string_lossy()
            .replace('\\', "/");
        if rel == REGISTRY {
            continue;
        }
        let text = std::fs::read_to_string(&f).unwrap();
        let ts: proc_macro2::TokenStream = text.parse().unwrap_or_else(|e| panic!("{rel}: {e:?}"));
        let (mut idents, mut pairs) = (BTreeSet::new(), BTreeSet::new());
        names(ts, &mut idents, &mut pairs);
        for m in &NAMED_MODELS {
            if m.home.contains(&rel.as_str()) {
                continue;
            }
            let named = m.idents.iter().any(|i| idents.contains(*i))
                || m.pairs
                    .iter()
                    .any(|(a, b)| pairs.contains(&(a.to_string(), b.to_string())));
            if named {
                out.get_mut(m.name).unwrap().push(rel.clone());
            }
        }
    }
    out
}

/// Each model is named (its types, its core module, its enum variants)
/// in at most [`MAX_FILES`] files of the simulator and the Python bindings outside its own
/// plant file, its core folder and the registry. Prints the counts and the files
/// (`cargo test -p shimmy-tests --test cross_crate each_model -- --nocapture`).
#[test]
fn each_model_is_named_in_few_files_outside_its_own() {
    let counts = files_naming_each_model();
    let mut bad = Vec::new();
    for (model, max) in MAX_FILES {
        let files = &counts[model];
        println!("{model}: {} files", files.len());
        for f in files {
            println!("    {f}");
        }
        if files.len() > max {
            bad.push(format!(
                "{model}: {} files name it, at most {max}: {files:#?}",
                files.len()
            ));
        }
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
    // The model added last, with no study of its own, is its core folder, its plant file and
    // its registry line: no other file names it.
    let newest = &counts["towed-wheel-string"];
    assert!(newest.is_empty(), "the towed wheel is named in {newest:#?}");
}

/// The count sees a model named in code, in a macro's arguments and in a grouped `use`, and
/// not in a comment or a string.
#[test]
fn the_model_count_sees_names_in_code_not_in_comments() {
    let count = |src: &str| {
        let (mut idents, mut pairs) = (BTreeSet::new(), BTreeSet::new());
        names(src.parse().unwrap(), &mut idents, &mut pairs);
        let m = &NAMED_MODELS[1];
        m.idents.iter().any(|i| idents.contains(*i))
            || m.pairs
                .iter()
                .any(|(a, b)| pairs.contains(&(a.to_string(), b.to_string())))
    };
    assert!(count("fn f() { let _ = TruckParams::NAME; }"));
    assert!(count("fn f() { bail!(\"{}\", x::TRUCK_FIELDS.len()); }"));
    assert!(count("use shimmy_core::vehicles::{car, truck};"));
    assert!(count("fn f(v: V) { if let ModelVehicle::Truck(t) = v {} }"));
    assert!(!count("// TruckParams\n/// `ModelVehicle::Truck`\nfn f() { let s = \"TruckSet\"; let truck = 1; }"));
    assert!(!count(
        "pub mod truck_plant;\n#[cfg(test)]\nmod tests { use super::TruckSet; }"
    ));
    assert!(count(
        "#[cfg(test)]\nmod tests {}\nfn f() -> TruckParams { todo!() }"
    ));
    assert!(count(
        "#[cfg(test)]\nuse a::b;\nfn f() -> TruckParams { todo!() }"
    ));
}
