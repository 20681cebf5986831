//! Fake Quanser HIL library (being written).
