//! The `.plant` model language.
