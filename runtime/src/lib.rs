//! plantc-runtime (filled by a later issue).
