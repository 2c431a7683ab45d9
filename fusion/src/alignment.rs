//! OWNER: filter helper.
