//! plantc-identify (filled by a later issue).
