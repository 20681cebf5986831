//! Run-time binding of the Quanser HIL C API (`hil.dll` / `libhil.so`).
//!
//! Only the functions the Q2-USB backend needs are bound, with the exact C
//! types of `hil.h`. The library is loaded with `libloading`, so plantc builds
//! and tests without the Quanser SDK.

#![allow(non_camel_case_types)]

use crate::backend::BackendError;
use libloading::Library;
use std::ffi::{c_char, c_int, c_uint, c_void, CStr};
use std::path::{Path, PathBuf};

/// `t_int`.
pub type t_int = c_int;
/// `t_uint`.
pub type t_uint = c_uint;
/// `t_error`: < 0 is an error code; >= 0 success or a count.
pub type t_error = t_int;
/// `t_int32`.
pub type t_int32 = i32;
/// `t_uint32`.
pub type t_uint32 = u32;
/// `t_double`.
pub type t_double = f64;
/// `t_boolean`.
pub type t_boolean = c_char;
/// `t_clock`.
pub type t_clock = c_int;

/// Opaque `struct tag_card`.
#[repr(C)]
pub struct tag_card {
    _private: [u8; 0],
}
/// Opaque `struct tag_task`.
#[repr(C)]
pub struct tag_task {
    _private: [u8; 0],
}
/// `t_card`: a board handle.
pub type t_card = *mut tag_card;
/// `t_task`: a task handle.
pub type t_task = *mut tag_task;

/// The board's first hardware clock, used as the loop clock.
pub const HARDWARE_CLOCK_0: t_clock = 0;
/// `INFINITE` number of samples for `hil_task_start` (-1 as `t_uint32`).
pub const INFINITE: t_uint32 = u32::MAX;

/// `hil_open`.
pub type FnOpen = unsafe extern "C" fn(*const c_char, *const c_char, *mut t_card) -> t_error;
/// `hil_close`, `hil_watchdog_reload`, `hil_watchdog_stop`, `hil_watchdog_clear`,
/// `hil_watchdog_is_expired`.
pub type FnCard = unsafe extern "C" fn(t_card) -> t_error;
/// `hil_set_card_specific_options`.
pub type FnSetOptions = unsafe extern "C" fn(t_card, *const c_char, usize) -> t_error;
/// `hil_set_encoder_counts`.
pub type FnSetEncoderCounts =
    unsafe extern "C" fn(t_card, *const t_uint32, t_uint32, *const t_int32) -> t_error;
/// `hil_read_encoder`.
pub type FnReadEncoder =
    unsafe extern "C" fn(t_card, *const t_uint32, t_uint32, *mut t_int32) -> t_error;
/// `hil_write_analog`.
pub type FnWriteAnalog =
    unsafe extern "C" fn(t_card, *const t_uint32, t_uint32, *const t_double) -> t_error;
/// `hil_set_analog_output_ranges`.
pub type FnSetAnalogOutputRanges = unsafe extern "C" fn(
    t_card,
    *const t_uint32,
    t_uint32,
    *const t_double,
    *const t_double,
) -> t_error;
/// `hil_watchdog_set_analog_expiration_state`.
pub type FnWatchdogSetAnalog =
    unsafe extern "C" fn(t_card, *const t_uint, t_uint, *const t_double) -> t_error;
/// `hil_watchdog_start`.
pub type FnWatchdogStart = unsafe extern "C" fn(t_card, t_double) -> t_error;
/// `hil_task_create_encoder_reader`.
pub type FnTaskCreateEncoderReader =
    unsafe extern "C" fn(t_card, t_uint32, *const t_uint32, t_uint32, *mut t_task) -> t_error;
/// `hil_task_start`.
pub type FnTaskStart = unsafe extern "C" fn(t_task, t_clock, t_double, t_uint32) -> t_error;
/// `hil_task_read_encoder`.
pub type FnTaskReadEncoder = unsafe extern "C" fn(t_task, t_uint32, *mut t_int32) -> t_error;
/// `hil_task_stop`, `hil_task_delete`.
pub type FnTask = unsafe extern "C" fn(t_task) -> t_error;
/// `msg_get_error_messageA`.
pub type FnGetErrorMessage =
    unsafe extern "C" fn(*const c_char, t_error, *mut c_char, usize) -> t_error;

/// The encoder-reader task functions (all present or the task mode is unavailable).
#[derive(Clone, Copy)]
pub struct TaskApi {
    /// `hil_task_create_encoder_reader`.
    pub create_encoder_reader: FnTaskCreateEncoderReader,
    /// `hil_task_start`.
    pub start: FnTaskStart,
    /// `hil_task_read_encoder`.
    pub read_encoder: FnTaskReadEncoder,
    /// `hil_task_stop`.
    pub stop: FnTask,
    /// `hil_task_delete`.
    pub delete: FnTask,
}

/// The loaded HIL library with its function pointers. The pointers stay
/// valid while this value (which owns the `Library`) lives.
pub struct HilApi {
    /// `hil_open`.
    pub open: FnOpen,
    /// `hil_close`.
    pub close: FnCard,
    /// `hil_set_card_specific_options` (optional).
    pub set_card_specific_options: Option<FnSetOptions>,
    /// `hil_set_encoder_counts`.
    pub set_encoder_counts: FnSetEncoderCounts,
    /// `hil_read_encoder`.
    pub read_encoder: FnReadEncoder,
    /// `hil_write_analog`.
    pub write_analog: FnWriteAnalog,
    /// `hil_set_analog_output_ranges` (optional).
    pub set_analog_output_ranges: Option<FnSetAnalogOutputRanges>,
    /// `hil_watchdog_set_analog_expiration_state` (optional: absent = no watchdog).
    pub watchdog_set_analog_expiration_state: Option<FnWatchdogSetAnalog>,
    /// `hil_watchdog_start` (optional).
    pub watchdog_start: Option<FnWatchdogStart>,
    /// `hil_watchdog_reload` (optional).
    pub watchdog_reload: Option<FnCard>,
    /// `hil_watchdog_stop` (optional).
    pub watchdog_stop: Option<FnCard>,
    /// `hil_watchdog_clear` (optional).
    pub watchdog_clear: Option<FnCard>,
    /// `hil_watchdog_is_expired` (optional): > 0 expired, 0 not, < 0 error.
    pub watchdog_is_expired: Option<FnCard>,
    /// The encoder-reader task functions, if all are exported.
    pub task: Option<TaskApi>,
    /// `msg_get_error_messageA` (from the HIL library or `quanser_common`).
    pub get_error_message: Option<FnGetErrorMessage>,
    /// The path the library was loaded from.
    pub path: PathBuf,
    _messages_lib: Option<Library>,
    _lib: Library,
}

/// Default library names tried when no path is configured.
pub fn default_library_candidates() -> Vec<PathBuf> {
    if cfg!(windows) {
        vec![PathBuf::from("hil.dll")]
    } else if cfg!(target_os = "macos") {
        vec![PathBuf::from("libhil.dylib")]
    } else {
        vec![
            PathBuf::from("libhil.so"),
            PathBuf::from("/opt/quanser/lib/libhil.so"),
        ]
    }
}

fn message_library_candidates() -> Vec<PathBuf> {
    if cfg!(windows) {
        vec![PathBuf::from("quanser_common.dll")]
    } else {
        vec![
            PathBuf::from("libquanser_common.so"),
            PathBuf::from("/opt/quanser/lib/libquanser_common.so"),
        ]
    }
}

/// Looks up a symbol and copies out the function pointer.
///
/// # Safety
/// `T` must be the symbol's true C signature.
unsafe fn sym<T: Copy>(lib: &Library, name: &'static str) -> Option<T> {
    let mut z = Vec::with_capacity(name.len() + 1);
    z.extend_from_slice(name.as_bytes());
    z.push(0);
    lib.get::<T>(&z).ok().map(|s| *s)
}

unsafe fn req<T: Copy>(lib: &Library, name: &'static str) -> Result<T, BackendError> {
    sym(lib, name).ok_or(BackendError::MissingSymbol(name))
}

/// Where a configured library path is loaded from: a bare file name
/// (`libhil.so`, no directory) names a file in the current directory when
/// one exists there (the loader alone would search only the system library
/// path, and could load a system library of the same name); otherwise the
/// name is left to the system search. Paths with a directory are used as
/// given.
pub fn resolve_library_path(path: &Path) -> PathBuf {
    let bare = path.parent().is_some_and(|d| d.as_os_str().is_empty());
    if bare {
        let local = Path::new(".").join(path);
        if local.is_file() {
            return std::fs::canonicalize(&local).unwrap_or(local);
        }
    }
    path.to_path_buf()
}

impl HilApi {
    /// Loads the HIL library from `path` (see [`resolve_library_path`]), or
    /// from the default names if `None`. A library without the HIL API is a
    /// [`BackendError::Load`] naming what was loaded.
    pub fn load(path: Option<&Path>) -> Result<Self, BackendError> {
        let candidates = match path {
            Some(p) => vec![resolve_library_path(p)],
            None => default_library_candidates(),
        };
        let mut tried = Vec::new();
        for p in &candidates {
            // SAFETY: loading a library runs its initialisers; this is the
            // HIL library the user configured, which is the point.
            match unsafe { Library::new(p) } {
                Ok(lib) => {
                    return Self::from_library(lib, p.clone()).map_err(|e| match e {
                        BackendError::MissingSymbol(s) => BackendError::Load {
                            path: p.display().to_string(),
                            reason: format!("it loaded, but is not a HIL library (no `{s}`)"),
                        },
                        e => e,
                    })
                }
                Err(e) => tried.push((p.display().to_string(), e.to_string())),
            }
        }
        let path = tried
            .iter()
            .map(|(p, _)| p.as_str())
            .collect::<Vec<_>>()
            .join(", then ");
        let mut reason = tried
            .last()
            .map_or_else(|| "no candidate".to_string(), |(_, r)| r.clone());
        if path.is_empty() || candidates.len() > 1 {
            reason.push_str(" (give the library with --hil-lib PATH)");
        }
        Err(BackendError::Load { path, reason })
    }

    /// Where the library was loaded from, for a note: the path and whether
    /// the system's library search found it.
    pub fn origin(&self) -> String {
        if self.path.parent().is_some_and(|d| d.as_os_str().is_empty()) {
            format!(
                "`{}` (found on the system library path)",
                self.path.display()
            )
        } else {
            format!("`{}`", self.path.display())
        }
    }

    fn from_library(lib: Library, path: PathBuf) -> Result<Self, BackendError> {
        // SAFETY: every signature below is copied from hil.h / quanser_messages.h.
        unsafe {
            let task = match (
                sym::<FnTaskCreateEncoderReader>(&lib, "hil_task_create_encoder_reader"),
                sym::<FnTaskStart>(&lib, "hil_task_start"),
                sym::<FnTaskReadEncoder>(&lib, "hil_task_read_encoder"),
                sym::<FnTask>(&lib, "hil_task_stop"),
                sym::<FnTask>(&lib, "hil_task_delete"),
            ) {
                (Some(c), Some(s), Some(r), Some(st), Some(d)) => Some(TaskApi {
                    create_encoder_reader: c,
                    start: s,
                    read_encoder: r,
                    stop: st,
                    delete: d,
                }),
                _ => None,
            };
            let mut get_error_message = sym::<FnGetErrorMessage>(&lib, "msg_get_error_messageA");
            let mut messages_lib = None;
            if get_error_message.is_none() {
                for p in message_library_candidates() {
                    if let Ok(m) = Library::new(&p) {
                        get_error_message = sym::<FnGetErrorMessage>(&m, "msg_get_error_messageA");
                        if get_error_message.is_some() {
                            messages_lib = Some(m);
                            break;
                        }
                    }
                }
            }
            Ok(Self {
                open: req(&lib, "hil_open")?,
                close: req(&lib, "hil_close")?,
                set_card_specific_options: sym(&lib, "hil_set_card_specific_options"),
                set_encoder_counts: req(&lib, "hil_set_encoder_counts")?,
                read_encoder: req(&lib, "hil_read_encoder")?,
                write_analog: req(&lib, "hil_write_analog")?,
                set_analog_output_ranges: sym(&lib, "hil_set_analog_output_ranges"),
                watchdog_set_analog_expiration_state: sym(
                    &lib,
                    "hil_watchdog_set_analog_expiration_state",
                ),
                watchdog_start: sym(&lib, "hil_watchdog_start"),
                watchdog_reload: sym(&lib, "hil_watchdog_reload"),
                watchdog_stop: sym(&lib, "hil_watchdog_stop"),
                watchdog_clear: sym(&lib, "hil_watchdog_clear"),
                watchdog_is_expired: sym(&lib, "hil_watchdog_is_expired"),
                task,
                get_error_message,
                path,
                _messages_lib: messages_lib,
                _lib: lib,
            })
        }
    }

    /// Quanser's message for `code` (via `msg_get_error_messageA`), or a fallback text.
    pub fn error_message(&self, code: t_error) -> String {
        if let Some(f) = self.get_error_message {
            let mut buf = [0 as c_char; 512];
            // SAFETY: buffer and length match; a null locale selects the default.
            let r = unsafe { f(std::ptr::null(), code, buf.as_mut_ptr(), buf.len()) };
            if r >= 0 {
                buf[buf.len() - 1] = 0;
                // SAFETY: NUL-terminated above.
                let s = unsafe { CStr::from_ptr(buf.as_ptr()) };
                let s = s.to_string_lossy().trim().to_string();
                if !s.is_empty() {
                    return s;
                }
            }
        }
        format!("HIL error {code} (no message available)")
    }

    /// Builds a [`BackendError::Hil`] for a failed call.
    pub fn error(&self, function: &'static str, code: t_error) -> BackendError {
        BackendError::Hil {
            function,
            code,
            message: self.error_message(code),
        }
    }
}

/// A null card handle.
pub fn null_card() -> t_card {
    std::ptr::null_mut::<c_void>().cast()
}

/// A null task handle.
pub fn null_task() -> t_task {
    std::ptr::null_mut::<c_void>().cast()
}
