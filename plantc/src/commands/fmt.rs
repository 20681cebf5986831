//! `plantc fmt`: format model files in the canonical layout.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use plantc_derive::lang::format::{format, FormatError};
use plantc_derive::lang::{render, SourceFile};

use crate::common::CliError;
use crate::{EXIT_BAD_INPUT, EXIT_FAILURE};

pub fn run(
    paths: &[PathBuf],
    check: bool,
    out: &mut dyn Write,
    err: &mut dyn Write,
) -> Result<(), CliError> {
    if paths.iter().any(|p| p.as_os_str() == "-") {
        if paths.len() > 1 {
            return Err(CliError::input(
                "error: `-` (standard input) cannot be mixed with files",
            ));
        }
        let mut text = String::new();
        std::io::stdin()
            .read_to_string(&mut text)
            .map_err(|e| CliError::input(format!("error: reading standard input: {e}")))?;
        let formatted = format(&text).map_err(|e| format_error("<stdin>", &text, e))?;
        if check {
            if formatted != text {
                return Err(CliError::failure("<stdin>: not formatted"));
            }
            return Ok(());
        }
        let _ = write!(out, "{formatted}");
        return Ok(());
    }
    let mut files = Vec::new();
    for p in paths {
        collect(p, &mut files)?;
    }
    let mut unformatted = 0;
    // exit code of the worst problem with a file (they are reported as they come)
    let mut failed: Option<i32> = None;
    for path in &files {
        let name = path.display().to_string();
        let text = match plantc_derive::model::read_regular_file(path).and_then(|b| {
            String::from_utf8(b)
                .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidData, e))
        }) {
            Ok(t) => t,
            Err(e) => {
                let _ = writeln!(err, "error: cannot read {name}: {e}");
                failed = failed.max(Some(EXIT_BAD_INPUT));
                continue;
            }
        };
        let formatted = match format(&text) {
            Ok(f) => f,
            Err(e) => {
                let e = format_error(&name, &text, e);
                let _ = write!(err, "{}", e.message);
                failed = failed.max(Some(e.code));
                continue;
            }
        };
        if formatted == text {
            continue;
        }
        unformatted += 1;
        if check {
            let line = first_difference(&text, &formatted);
            let _ = writeln!(
                out,
                "{name}: not formatted (first difference on line {line})"
            );
        } else {
            // crash-safe: a temporary file in the same directory, synced and
            // renamed over the original (permissions and symbolic links kept;
            // a read-only file is refused)
            if let Err(e) = plantc_fsio::write_atomic(path, &formatted) {
                let _ = writeln!(err, "error: {e} (the file is unchanged)");
                failed = failed.max(Some(EXIT_FAILURE));
                continue;
            }
            let _ = writeln!(out, "formatted {name}");
        }
    }
    if let Some(code) = failed {
        return Err(CliError {
            message: "error: some files could not be formatted (see above); the others were".into(),
            code,
        });
    }
    if check && unformatted > 0 {
        return Err(CliError {
            message: format!("{unformatted} file(s) not formatted; run `plantc fmt` on them"),
            code: EXIT_FAILURE,
        });
    }
    Ok(())
}

fn format_error(name: &str, text: &str, e: FormatError) -> CliError {
    match e {
        FormatError::Syntax(d) => CliError::input(format!(
            "{}{name}: not formatted: fix the syntax errors first\n",
            render(&SourceFile::new(name, text), &d)
        )),
        other => CliError::failure(format!("error: {name}: {other}\n")),
    }
}

/// `path` itself, or the `*.plant` files under a directory (sorted). The
/// walk does not follow symbolic links to directories (a link back to `.`
/// would list the same files again, two would never end); a file reached
/// twice (through a link) is formatted once.
fn collect(path: &Path, files: &mut Vec<PathBuf>) -> Result<(), CliError> {
    let mut seen = std::collections::BTreeSet::new();
    if path.is_dir() {
        walk(path, files, &mut seen)
    } else if path.exists() {
        files.push(path.to_path_buf());
        Ok(())
    } else {
        Err(CliError::input(format!(
            "error: {}: no such file or directory",
            path.display()
        )))
    }
}

fn walk(
    dir: &Path,
    files: &mut Vec<PathBuf>,
    seen: &mut std::collections::BTreeSet<PathBuf>,
) -> Result<(), CliError> {
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| CliError::input(format!("error: cannot read {}: {e}", dir.display())))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .collect();
    entries.sort();
    for p in entries {
        let link = std::fs::symlink_metadata(&p).is_ok_and(|m| m.file_type().is_symlink());
        if p.is_dir() {
            if !link {
                walk(&p, files, seen)?;
            }
        } else if p.extension().is_some_and(|x| x == "plant")
            && seen.insert(std::fs::canonicalize(&p).unwrap_or_else(|_| p.clone()))
        {
            files.push(p);
        }
    }
    Ok(())
}

/// 1-based number of the first line that differs.
fn first_difference(a: &str, b: &str) -> usize {
    a.lines()
        .zip(b.lines())
        .position(|(x, y)| x != y)
        .unwrap_or_else(|| a.lines().count().min(b.lines().count()))
        + 1
}
