//! Unit tests of the writers' private helpers; the round trips through the TDM and IOD
//! parsers, and the writers' public behaviour, are in `tests/it/formats.rs`.

use super::*;

#[test]
fn mx_encode_picks_the_smallest_code_not_below_the_value() {
    assert_eq!(mx_encode(0.1).as_deref(), Some("17"));
    assert_eq!(mx_encode(0.3).as_deref(), Some("37"));
    assert_eq!(mx_encode(0.05).as_deref(), Some("56"));
    assert_eq!(mx_encode(0.31).as_deref(), Some("47"));
    assert_eq!(mx_encode(1.0).as_deref(), Some("18"));
    assert_eq!(mx_encode(1.0001).as_deref(), Some("28"));
    assert_eq!(mx_encode(9.5).as_deref(), Some("19"));
    assert_eq!(mx_encode(0.0).as_deref(), Some("10"));
    assert_eq!(mx_encode(90.0).as_deref(), Some("99"));
    assert_eq!(mx_encode(90.1), None);
    assert_eq!(mx_encode(-0.1), None);
}
