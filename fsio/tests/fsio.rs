//! Behaviour of the crash-safe writers: contents, what survives, what is
//! cleaned, and the repair of a run killed mid-swap (simulated by creating
//! the temporaries a killed process leaves, with a process id that is not
//! running).

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use plantc_fsio::{probe_writable, write_atomic, write_if_changed, AtomicFile, Error, FreshDir};

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("plantc-fsio-{}-{name}", std::process::id()));
    let _ = fs::remove_dir_all(&d);
    fs::create_dir_all(&d).unwrap();
    d
}

fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// A process id that is not running (Linux pids are below 2^22).
const DEAD: u32 = 999_999_999;

#[test]
fn write_atomic_creates_and_replaces_without_leaving_temporaries() {
    let d = tmp("replace");
    let p = d.join("model.plant");
    write_atomic(&p, "one\n").unwrap();
    assert_eq!(fs::read_to_string(&p).unwrap(), "one\n");
    write_atomic(&p, "two, longer\n").unwrap();
    assert_eq!(fs::read_to_string(&p).unwrap(), "two, longer\n");
    assert_eq!(names(&d), ["model.plant"]);
}

#[test]
fn uncommitted_file_leaves_the_old_one_complete() {
    let d = tmp("uncommitted");
    let p = d.join("fitted.plant");
    fs::write(&p, "old complete\n").unwrap();
    {
        let mut f = AtomicFile::create(&p).unwrap();
        f.write_all(b"new, half").unwrap();
        // dropped: as if the computation failed half way
    }
    assert_eq!(fs::read_to_string(&p).unwrap(), "old complete\n");
    assert_eq!(names(&d), ["fitted.plant"]);
}

#[test]
fn temporaries_of_a_killed_process_are_removed_by_the_next_write() {
    let d = tmp("leftover");
    let stale = d.join(format!(".x.csv.plantc-tmp-{DEAD}-0"));
    fs::write(&stale, "half").unwrap();
    // another target's temporary and a user's file are not touched
    let other = d.join(format!(".y.csv.plantc-tmp-{DEAD}-0"));
    fs::write(&other, "half").unwrap();
    fs::write(d.join(".x.csv.notes"), "mine").unwrap();
    write_atomic(d.join("x.csv"), "t\n").unwrap();
    assert!(!stale.exists());
    assert!(other.exists());
    assert!(d.join(".x.csv.notes").exists());
}

#[test]
fn write_if_changed_leaves_an_identical_file_alone() {
    let d = tmp("unchanged");
    let p = d.join("gen.rs");
    assert!(write_if_changed(&p, "fn f() {}\n").unwrap());
    let before = fs::metadata(&p).unwrap().modified().unwrap();
    std::thread::sleep(std::time::Duration::from_millis(20));
    assert!(!write_if_changed(&p, "fn f() {}\n").unwrap());
    assert_eq!(fs::metadata(&p).unwrap().modified().unwrap(), before);
    assert!(write_if_changed(&p, "fn g() {}\n").unwrap());
}

#[cfg(unix)]
#[test]
fn permissions_and_symbolic_links_survive() {
    use std::os::unix::fs::PermissionsExt;
    let d = tmp("perms");
    let real = d.join("real.plant");
    fs::write(&real, "old").unwrap();
    fs::set_permissions(&real, fs::Permissions::from_mode(0o640)).unwrap();
    let link = d.join("link.plant");
    std::os::unix::fs::symlink("real.plant", &link).unwrap();
    write_atomic(&link, "new").unwrap();
    assert!(fs::symlink_metadata(&link)
        .unwrap()
        .file_type()
        .is_symlink());
    assert_eq!(fs::read_to_string(&real).unwrap(), "new");
    assert_eq!(
        fs::metadata(&real).unwrap().permissions().mode() & 0o777,
        0o640
    );
}

#[test]
fn errors_name_the_path_and_leave_nothing() {
    let d = tmp("errors");
    fs::write(d.join("a_file"), "x").unwrap();
    // parent is a file: no file can be created below it (even as root)
    let bad = d.join("a_file/out.plant");
    let e = write_atomic(&bad, "x").unwrap_err();
    assert!(matches!(e, Error::Write { .. }), "{e:?}");
    assert!(e.to_string().contains("a_file/out.plant"), "{e}");
    assert!(probe_writable(&bad).is_err());
    assert!(probe_writable(d.join("missing_dir/out.plant")).is_err());
    assert!(matches!(
        write_atomic(&d, "x").unwrap_err(),
        Error::WrongKind { .. }
    ));
    probe_writable(d.join("fine.plant")).unwrap();
    assert_eq!(names(&d), ["a_file"]);
}

/// Every file below `dir` (relative, `/`-separated) with its text; the
/// hidden `.plantc-` entries (manifest, staging, journal) left out.
fn tree(dir: &Path) -> Vec<(String, String)> {
    fn walk(root: &Path, d: &Path, out: &mut Vec<(String, String)>) {
        for e in fs::read_dir(d).unwrap().flatten() {
            let p = e.path();
            if e.file_name().to_string_lossy().starts_with(".plantc-") {
                continue;
            }
            if p.is_dir() {
                walk(root, &p, out);
            } else {
                let rel = p
                    .strip_prefix(root)
                    .unwrap()
                    .to_string_lossy()
                    .replace('\\', "/");
                out.push((rel, fs::read_to_string(&p).unwrap_or_default()));
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out);
    out.sort();
    out
}

fn t(pairs: &[(&str, &str)]) -> Vec<(String, String)> {
    let mut v: Vec<(String, String)> = pairs
        .iter()
        .map(|(a, b)| (a.to_string(), b.to_string()))
        .collect();
    v.sort();
    v
}

/// `files` committed into `out` by `owner`.
fn commit(out: &Path, owner: &str, files: &[(&str, &str)]) -> Result<(), Error> {
    let fresh = FreshDir::create(out, owner)?;
    for (rel, text) in files {
        let p = fresh.path().join(rel);
        fs::create_dir_all(p.parent().unwrap()).unwrap();
        write_atomic(&p, text).unwrap();
    }
    fresh.commit()
}

/// The user's files in an output directory (issue 31, reproducer r02):
/// names like identify's own (`<digits>-...`), inside its subdirectories.
const USERS: [(&str, &str); 4] = [
    ("2024-06-01-notes.txt", "notes"),
    ("3-extra.csv", "mine"),
    ("my_notes.txt", "mine"),
    ("3-fitted/mine.txt", "mine"),
];

#[test]
fn fresh_dir_replaces_only_its_own_files_and_never_moves_the_users() {
    let d = tmp("fresh");
    let out = d.join("out");
    commit(
        &out,
        "identify",
        &[("report.json", "old"), ("3-fitted/driven.svg", "old")],
    )
    .unwrap();
    for (rel, text) in USERS {
        fs::write(out.join(rel), text).unwrap();
    }
    let before = tree(&out);

    let fresh = FreshDir::create(&out, "identify").unwrap();
    fs::create_dir(fresh.path().join("1-nominal")).unwrap();
    write_atomic(fresh.path().join("1-nominal/driven.svg"), "new").unwrap();
    write_atomic(fresh.path().join("report.json"), "new").unwrap();
    // before the commit nothing changed
    assert_eq!(tree(&out), before);
    fresh.commit().unwrap();
    let mut expected = USERS.to_vec();
    expected.extend([("1-nominal/driven.svg", "new"), ("report.json", "new")]);
    // the stale 3-fitted/driven.svg is gone, its directory stays (the user's file)
    assert_eq!(tree(&out), t(&expected));
    assert_eq!(names(&d), ["out"], "no temporaries next to it");
    let hidden: Vec<String> = names(&out)
        .into_iter()
        .filter(|n| n.starts_with(".plantc-"))
        .collect();
    assert_eq!(hidden, [".plantc-manifest-identify"]);
    let listed = plantc_fsio::manifest(&out, "identify").unwrap();
    assert_eq!(
        listed
            .iter()
            .map(|p| p.to_string_lossy().replace('\\', "/"))
            .collect::<Vec<_>>(),
        ["1-nominal/driven.svg", "report.json"]
    );

    // an abandoned run changes nothing and leaves nothing
    let fresh = FreshDir::create(&out, "identify").unwrap();
    write_atomic(fresh.path().join("report.json"), "newer, unfinished").unwrap();
    drop(fresh);
    assert_eq!(tree(&out), t(&expected));
    assert_eq!(names(&out).len(), 7, "{:?}", names(&out));
}

#[test]
fn another_owners_files_and_unlisted_files_are_not_replaced_without_asking() {
    let d = tmp("unlisted");
    let out = d.join("data");
    // synth's recordings, then the user's notes at a path gen writes
    commit(&out, "synth", &[("run1.csv", "t\n")]).unwrap();
    fs::write(out.join("README.md"), "mine").unwrap();
    let before = tree(&out);
    let e = commit(&out, "gen", &[("Cargo.toml", "x"), ("README.md", "gen")]).unwrap_err();
    assert!(matches!(e, Error::WouldReplace { .. }), "{e}");
    assert!(e.to_string().contains("--force"), "{e}");
    assert_eq!(tree(&out), before, "nothing moved on a refusal");
    // gen's commit does not delete synth's listed file either
    let e = commit(&out, "gen", &[("run1.csv", "gen")]).unwrap_err();
    assert!(matches!(e, Error::WouldReplace { .. }), "{e}");
    // with --force the file at gen's path is replaced, nothing else touched
    let fresh = FreshDir::create(&out, "gen")
        .unwrap()
        .replace_unlisted(true);
    write_atomic(fresh.path().join("README.md"), "gen").unwrap();
    fresh.commit().unwrap();
    assert_eq!(tree(&out), t(&[("README.md", "gen"), ("run1.csv", "t\n")]));
    // and gen's next version without README.md deletes only its own file
    commit(&out, "gen", &[("Cargo.toml", "x")]).unwrap();
    assert_eq!(tree(&out), t(&[("Cargo.toml", "x"), ("run1.csv", "t\n")]));
}

#[test]
fn earlier_files_kept_when_asked_and_legacy_files_adopted() {
    let d = tmp("keep");
    let out = d.join("data");
    commit(&out, "synth", &[("a.csv", "1"), ("truth.json", "1")]).unwrap();
    let fresh = FreshDir::create(&out, "synth")
        .unwrap()
        .keep_earlier_files();
    write_atomic(fresh.path().join("b.csv"), "2").unwrap();
    fresh.commit().unwrap();
    assert_eq!(
        tree(&out),
        t(&[("a.csv", "1"), ("b.csv", "2"), ("truth.json", "1")])
    );
    assert_eq!(plantc_fsio::manifest(&out, "synth").unwrap().len(), 3);

    // a directory from before manifests: the adopted file is plantc's
    let old = d.join("crate");
    fs::create_dir_all(old.join("src")).unwrap();
    fs::write(old.join("src/lib.rs"), "// @generated").unwrap();
    fs::write(old.join("src/mine.rs"), "mine").unwrap();
    let fresh = FreshDir::create(&old, "gen")
        .unwrap()
        .adopt("src/lib.rs")
        .adopt("../escape");
    fs::create_dir_all(fresh.path().join("src")).unwrap();
    write_atomic(fresh.path().join("src/main.rs"), "new").unwrap();
    fresh.commit().unwrap();
    assert_eq!(
        tree(&old),
        t(&[("src/main.rs", "new"), ("src/mine.rs", "mine")])
    );
}

#[test]
fn an_unchanged_file_keeps_its_modification_time() {
    let d = tmp("mtime");
    let out = d.join("crate");
    commit(&out, "gen", &[("Cargo.toml", "same"), ("src/lib.rs", "v1")]).unwrap();
    let before = fs::metadata(out.join("Cargo.toml"))
        .unwrap()
        .modified()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(20));
    commit(&out, "gen", &[("Cargo.toml", "same"), ("src/lib.rs", "v2")]).unwrap();
    assert_eq!(
        fs::metadata(out.join("Cargo.toml"))
            .unwrap()
            .modified()
            .unwrap(),
        before
    );
    assert_eq!(fs::read_to_string(out.join("src/lib.rs")).unwrap(), "v2");
}

#[test]
fn symbolic_links_files_and_read_only_files_are_refused() {
    let d = tmp("refusals");
    let out = d.join("a/b/out");
    commit(&out, "gen", &[("x", "1")]).unwrap();
    assert_eq!(names(&out), [".plantc-manifest-gen", "x"]);
    fs::write(d.join("file"), "").unwrap();
    assert!(matches!(
        FreshDir::create(d.join("file"), "gen").unwrap_err(),
        Error::WrongKind { .. }
    ));
    #[cfg(unix)]
    {
        // an output path that is a link: refused, the link and its target kept
        std::os::unix::fs::symlink("a/b/out", d.join("link")).unwrap();
        let e = FreshDir::create(d.join("link"), "gen").unwrap_err();
        assert!(matches!(e, Error::SymbolicLink { .. }), "{e}");
        assert!(e.to_string().contains("a/b/out"), "{e}");
        assert!(fs::symlink_metadata(d.join("link"))
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(tree(&out), t(&[("x", "1")]));
    }
    // a read-only file: write_atomic and a commit refuse to replace it
    let ro = out.join("x");
    let mut perm = fs::metadata(&ro).unwrap().permissions();
    perm.set_readonly(true);
    fs::set_permissions(&ro, perm).unwrap();
    let e = write_atomic(&ro, "2").unwrap_err();
    assert!(matches!(e, Error::ReadOnly { .. }), "{e}");
    let e = commit(&out, "gen", &[("x", "2")]).unwrap_err();
    assert!(matches!(e, Error::ReadOnly { .. }), "{e}");
    let e = commit(&out, "gen", &[("y", "2")]).unwrap_err();
    assert!(
        matches!(e, Error::ReadOnly { .. }),
        "deleting it is refused too: {e}"
    );
    assert_eq!(fs::read_to_string(&ro).unwrap(), "1");
}

#[test]
fn a_commit_killed_half_way_is_finished_by_the_next_run() {
    // the killed run had journaled its commit, moved report.json in and not
    // yet moved 1-nominal/a.svg nor deleted the stale figure
    let d = tmp("repair_commit");
    let out = d.join("out");
    commit(
        &out,
        "identify",
        &[("report.json", "old"), ("2-stale/b.svg", "old")],
    )
    .unwrap();
    fs::write(out.join("notes.txt"), "mine").unwrap();
    let staging = out.join(format!(".plantc-new-{DEAD}-4"));
    fs::create_dir_all(staging.join("1-nominal")).unwrap();
    fs::write(staging.join("1-nominal/a.svg"), "new").unwrap();
    fs::write(out.join("report.json"), "new").unwrap();
    fs::write(
        out.join(format!(".plantc-commit-{DEAD}-4")),
        "owner identify\n+ 1-nominal/a.svg\n+ report.json\n- 2-stale/b.svg\n= 1-nominal/a.svg\n= report.json\n",
    )
    .unwrap();
    // and another killed run had only begun writing
    fs::create_dir_all(out.join(format!(".plantc-new-{DEAD}-5"))).unwrap();
    drop(FreshDir::create(&out, "identify").unwrap());
    assert_eq!(
        tree(&out),
        t(&[
            ("1-nominal/a.svg", "new"),
            ("notes.txt", "mine"),
            ("report.json", "new")
        ])
    );
    assert_eq!(
        names(&out),
        [
            ".plantc-manifest-identify",
            "1-nominal",
            "notes.txt",
            "report.json"
        ]
    );
}

#[test]
fn a_swap_killed_between_its_two_renames_is_repaired() {
    // the two-rename fallback moved `out` aside, then died
    let d = tmp("repair_old");
    let out = d.join("out");
    let old = d.join(format!(".out.plantc-old-{DEAD}-3"));
    let new = d.join(format!(".out.plantc-new-{DEAD}-3"));
    fs::create_dir_all(&old).unwrap();
    fs::write(old.join("report.json"), "old complete").unwrap();
    fs::create_dir_all(&new).unwrap();
    fs::write(new.join("report.json"), "new complete").unwrap();
    let fresh = FreshDir::create(&out, "identify").unwrap();
    assert_eq!(
        fs::read_to_string(out.join("report.json")).unwrap(),
        "old complete"
    );
    drop(fresh);
    assert_eq!(names(&d), ["out"]);
    assert_eq!(names(&out), ["report.json"]);
}

#[test]
fn entries_carried_by_a_killed_run_go_back() {
    let d = tmp("repair_carried");
    let out = d.join("crate");
    fs::create_dir_all(&out).unwrap();
    fs::write(out.join("Cargo.toml"), "old").unwrap();
    // the killed run had moved target/ into its unfinished new directory
    let new = d.join(format!(".crate.plantc-new-{DEAD}-7"));
    fs::create_dir_all(new.join("target")).unwrap();
    fs::write(new.join("target/cache"), "c").unwrap();
    fs::write(new.join("Cargo.toml"), "new, unfinished").unwrap();
    fs::write(
        d.join(format!(".crate.plantc-carried-{DEAD}-7")),
        "target\n",
    )
    .unwrap();
    drop(FreshDir::create(&out, "identify").unwrap());
    assert_eq!(names(&out), ["Cargo.toml", "target"]);
    assert_eq!(fs::read_to_string(out.join("Cargo.toml")).unwrap(), "old");
    assert_eq!(names(&d), ["crate"]);
}

#[test]
fn a_new_directory_appears_only_at_the_commit() {
    let d = tmp("new_dir");
    let out = d.join("a/out");
    let fresh = FreshDir::create(&out, "synth").unwrap();
    write_atomic(fresh.path().join("x.csv"), "1").unwrap();
    assert!(!out.exists(), "not before the commit");
    drop(fresh);
    assert!(!out.exists());
    assert_eq!(names(&d.join("a")), Vec::<String>::new(), "staging removed");
    commit(&out, "synth", &[("x.csv", "1")]).unwrap();
    assert_eq!(names(&out), [".plantc-manifest-synth", "x.csv"]);
    assert_eq!(names(&d.join("a")), ["out"]);
    // the target appearing meanwhile (someone else's file in it) is merged into
    let later = d.join("b");
    let fresh = FreshDir::create(&later, "synth").unwrap();
    write_atomic(fresh.path().join("y.csv"), "2").unwrap();
    fs::create_dir(&later).unwrap();
    fs::write(later.join("notes.txt"), "mine").unwrap();
    fresh.commit().unwrap();
    assert_eq!(tree(&later), t(&[("notes.txt", "mine"), ("y.csv", "2")]));
}

/// Issue 31 (r09): `finish_interrupted` carries out a journaled commit a
/// killed run left (as `FreshDir::create` does), for the commands that judge
/// a directory by its contents before creating anything; through a symbolic
/// link it does nothing.
#[test]
fn finish_interrupted_completes_a_journaled_commit_and_ignores_links() {
    let d = tmp("finish_interrupted");
    let out = d.join("out");
    commit(&out, "gen", &[("src/lib.rs", "old")]).unwrap();
    fs::write(out.join("notes.txt"), "mine").unwrap();
    fs::remove_file(out.join(".plantc-manifest-gen")).unwrap();
    let staging = out.join(format!(".plantc-new-{DEAD}-2"));
    fs::create_dir_all(staging.join("src")).unwrap();
    fs::write(staging.join("src/lib.rs"), "new").unwrap();
    let journal = "owner gen\n+ src/lib.rs\n= src/lib.rs\n";
    fs::write(out.join(format!(".plantc-commit-{DEAD}-2")), journal).unwrap();
    let link = d.join("link");
    std::os::unix::fs::symlink(&out, &link).unwrap();
    plantc_fsio::finish_interrupted(&link);
    assert!(
        plantc_fsio::manifest(&out, "gen").is_none(),
        "through a link"
    );
    plantc_fsio::finish_interrupted(&out);
    assert_eq!(
        tree(&out),
        t(&[("notes.txt", "mine"), ("src/lib.rs", "new")])
    );
    assert_eq!(names(&out), [".plantc-manifest-gen", "notes.txt", "src"]);
    // a path that does not exist: nothing made
    plantc_fsio::finish_interrupted(&d.join("absent"));
    assert!(!d.join("absent").exists());
}
