//! The symbolic core.
