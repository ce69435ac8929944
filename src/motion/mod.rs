//! Platform truth motion (to be written)
