//! plantc-codegen (filled by a later issue).
