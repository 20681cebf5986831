//! Numeric linear analysis and design.
