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

#[test]
fn fresh_dir_replaces_everything_and_keeps_the_old_until_commit() {
    let d = tmp("fresh");
    let out = d.join("out");
    fs::create_dir_all(out.join("3-fitted")).unwrap();
    fs::write(out.join("report.json"), "old").unwrap();
    fs::write(out.join("with_effect.plant"), "old").unwrap();
    fs::write(out.join("3-fitted/driven.svg"), "old").unwrap();

    let fresh = FreshDir::create(&out).unwrap();
    fs::create_dir(fresh.path().join("1-nominal")).unwrap();
    write_atomic(fresh.path().join("1-nominal/driven.svg"), "new").unwrap();
    // before the commit the old directory is intact
    assert_eq!(fs::read_to_string(out.join("report.json")).unwrap(), "old");
    write_atomic(fresh.path().join("report.json"), "new").unwrap();
    fresh.commit().unwrap();
    assert_eq!(names(&out), ["1-nominal", "report.json"]);
    assert_eq!(fs::read_to_string(out.join("report.json")).unwrap(), "new");
    assert_eq!(names(&d), ["out"], "no temporaries left");

    // an abandoned run changes nothing
    let fresh = FreshDir::create(&out).unwrap();
    write_atomic(fresh.path().join("report.json"), "newer, unfinished").unwrap();
    drop(fresh);
    assert_eq!(fs::read_to_string(out.join("report.json")).unwrap(), "new");
    assert_eq!(names(&d), ["out"]);
}

#[test]
fn fresh_dir_creates_missing_parents_and_refuses_a_file() {
    let d = tmp("fresh_new");
    let out = d.join("a/b/out");
    let fresh = FreshDir::create(&out).unwrap();
    write_atomic(fresh.path().join("x"), "1").unwrap();
    fresh.commit().unwrap();
    assert_eq!(names(&out), ["x"]);
    fs::write(d.join("file"), "").unwrap();
    assert!(matches!(
        FreshDir::create(d.join("file")).unwrap_err(),
        Error::WrongKind { .. }
    ));
}

#[test]
fn commit_keeping_carries_caches_over() {
    let d = tmp("keeping");
    let out = d.join("crate");
    fs::create_dir_all(out.join("target/debug")).unwrap();
    fs::write(out.join("target/debug/x"), "build cache").unwrap();
    fs::write(out.join("Cargo.lock"), "lock").unwrap();
    fs::write(out.join("Cargo.toml"), "old").unwrap();
    let fresh = FreshDir::create(&out).unwrap();
    write_atomic(fresh.path().join("Cargo.toml"), "new").unwrap();
    fresh
        .commit_keeping(|n| n == Path::new("target") || n == Path::new("Cargo.lock"))
        .unwrap();
    assert_eq!(names(&out), ["Cargo.lock", "Cargo.toml", "target"]);
    assert_eq!(fs::read_to_string(out.join("Cargo.toml")).unwrap(), "new");
    assert_eq!(
        fs::read_to_string(out.join("target/debug/x")).unwrap(),
        "build cache"
    );
    assert_eq!(names(&d), ["crate"]);
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
    let fresh = FreshDir::create(&out).unwrap();
    assert_eq!(
        fs::read_to_string(out.join("report.json")).unwrap(),
        "old complete"
    );
    drop(fresh);
    assert_eq!(names(&d), ["out"]);
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
    drop(FreshDir::create(&out).unwrap());
    assert_eq!(names(&out), ["Cargo.toml", "target"]);
    assert_eq!(fs::read_to_string(out.join("Cargo.toml")).unwrap(), "old");
    assert_eq!(names(&d), ["crate"]);
}

#[test]
fn the_current_directory_is_never_swapped_away() {
    let cwd = std::env::current_dir().unwrap();
    for p in [PathBuf::from("."), cwd.clone(), cwd.join("..")] {
        assert!(
            matches!(FreshDir::create(&p), Err(Error::CurrentDirectory { .. })),
            "{}",
            p.display()
        );
    }
}
