//! The scenario parser against random and mutated input: random text,
//! byte-level mutations of the paper scenario, its numbers replaced by
//! edge values (NaN, ±inf, 0, huge, tiny), and random formation trees.
//! Never a panic; whatever is accepted is consistent (one leader, every
//! parent present, every start pose resolved, the process table complete)
//! and survives a TOML round trip unchanged.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use proptest::prelude::*;
use shoal_scenario::{key_at, table_at, Scenario, PAPER_TOML};

/// What must hold for every scenario the parser accepts.
fn accepted_is_consistent(s: &Scenario) -> Result<(), TestCaseError> {
    let leaders = s.vehicles.iter().filter(|v| v.parent.is_none()).count();
    prop_assert_eq!(leaders, 1);
    for v in &s.vehicles {
        if let Some(p) = &v.parent {
            prop_assert!(s.vehicle(p).is_some(), "parent {} missing", p);
            prop_assert!(v.slot_m.is_some());
        }
    }
    let starts = s.start_poses();
    prop_assert_eq!(starts.len(), s.vehicles.len());
    for (p, yaw) in starts.values() {
        prop_assert!(p.iter().all(|x| x.is_finite()) && yaw.is_finite());
    }
    let followers = s.vehicles.len() - 1;
    let procs = s.processes();
    prop_assert_eq!(procs.len(), 2 + 4 * s.vehicles.len() + followers);
    for p in &procs {
        prop_assert!(p.divisor >= 1 && p.phase < p.divisor);
    }
    let _ = s.ticks();
    // Round trip: the resolved scenario a run writes down reads back the same.
    let text = s
        .to_toml()
        .map_err(|e| TestCaseError::fail(e.to_string()))?;
    let back =
        Scenario::from_toml(&text).map_err(|e| TestCaseError::fail(format!("{e}\n{text}")))?;
    // Compared as text: service sections may hold NaN (their own validate()
    // refuses it later), and NaN != NaN.
    let again = back
        .to_toml()
        .map_err(|e| TestCaseError::fail(e.to_string()))?;
    prop_assert_eq!(again, text);
    Ok(())
}

fn check(text: &str) -> Result<(), TestCaseError> {
    match Scenario::from_toml(text) {
        Ok(s) => accepted_is_consistent(&s),
        Err(e) => {
            prop_assert!(!e.to_string().is_empty());
            Ok(())
        }
    }
}

/// Byte offsets of every number in `text` (a run of digits, `.`, `e`, `-`, `+`
/// starting with a digit or sign).
fn numbers(text: &str) -> Vec<(usize, usize)> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let starts =
            b[i].is_ascii_digit() || (b[i] == b'-' && b.get(i + 1).is_some_and(u8::is_ascii_digit));
        let after_word = i > 0 && (b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_');
        if starts && !after_word {
            let mut j = i + 1;
            while j < b.len()
                && (b[j].is_ascii_digit()
                    || matches!(b[j], b'.' | b'e' | b'E' | b'-' | b'+' | b'_'))
            {
                j += 1;
            }
            out.push((i, j));
            i = j;
        } else {
            i += 1;
        }
    }
    out
}

const EDGE: &[&str] = &[
    "nan",
    "-nan",
    "inf",
    "-inf",
    "0",
    "0.0",
    "-0.0",
    "1e308",
    "-1e308",
    "5e-324",
    "1e-300",
    "9223372036854775807",
    "-9223372036854775808",
    "-1",
    "1",
    "0.5",
    "1e20",
    "3.0",
    "-8.0",
    "\"x\"",
    "[]",
    "[1.0]",
    "{}",
    "true",
];

proptest! {
    #![proptest_config(ProptestConfig { cases: 3000, ..ProptestConfig::default() })]

    #[test]
    fn random_text_never_panics(text in "\\PC{0,600}") {
        check(&text)?;
    }

    #[test]
    fn random_toml_like_text_never_panics(text in "([a-z_\\[\\]\\.=\" 0-9\\-]{0,30}\n){0,30}") {
        check(&text)?;
    }

    /// The paper scenario with one of its numbers replaced by an edge value.
    #[test]
    fn paper_with_an_edge_number_never_panics(which in any::<usize>(), edge in 0..EDGE.len()) {
        let nums = numbers(PAPER_TOML);
        let (a, b) = nums[which % nums.len()];
        let text = format!("{}{}{}", &PAPER_TOML[..a], EDGE[edge], &PAPER_TOML[b..]);
        check(&text)?;
    }

    /// The paper scenario with a few of its numbers replaced at once.
    #[test]
    fn paper_with_several_edge_numbers_never_panics(picks in prop::collection::vec((any::<usize>(), 0..EDGE.len()), 1..6)) {
        let nums = numbers(PAPER_TOML);
        let mut chosen: Vec<(usize, usize, &str)> = picks
            .iter()
            .map(|(w, e)| { let (a, b) = nums[w % nums.len()]; (a, b, EDGE[*e]) })
            .collect();
        chosen.sort_by_key(|c| std::cmp::Reverse(c.0));
        chosen.dedup_by_key(|c| c.0);
        let mut text = PAPER_TOML.to_string();
        for (a, b, e) in chosen {
            text.replace_range(a..b, e);
        }
        check(&text)?;
    }

    /// Byte-level mutations of the paper scenario: deletions, insertions of
    /// TOML punctuation, line duplications and swaps.
    #[test]
    fn mutated_paper_never_panics(
        del in (any::<usize>(), 0usize..40),
        ins in (any::<usize>(), "[\\[\\]=\"{},.#a-z0-9\n -]{0,16}"),
        dup in any::<usize>(),
        swap in (any::<usize>(), any::<usize>()),
        kind in 0u8..4,
    ) {
        let mut lines: Vec<String> = PAPER_TOML.lines().map(str::to_string).collect();
        let n = lines.len();
        let mut text = match kind {
            2 => { let l = lines[dup % n].clone(); lines.insert(dup % n, l); lines.join("\n") }
            3 => { lines.swap(swap.0 % n, swap.1 % n); lines.join("\n") }
            _ => PAPER_TOML.to_string(),
        };
        if kind == 0 {
            let a = del.0 % text.len();
            let b = (a + del.1).min(text.len());
            if text.is_char_boundary(a) && text.is_char_boundary(b) {
                text.replace_range(a..b, "");
            }
        }
        if kind == 1 {
            let a = ins.0 % (text.len() + 1);
            if text.is_char_boundary(a) {
                text.insert_str(a, &ins.1);
            }
        }
        check(&text)?;
    }

    /// Random formation trees: parents drawn from the vehicles, a missing
    /// name, or none; random slots. Accepted trees are real trees.
    #[test]
    fn random_formation_trees_never_panic(
        vehicles in prop::collection::vec((prop::option::of(0usize..12), -20.0f64..20.0, -20.0f64..20.0, -3.0f64..3.0), 1..10),
    ) {
        let mut text = String::from("name = \"tree\"\nduration_s = 5.0\n");
        let n = vehicles.len();
        for (i, (parent, x, y, z)) in vehicles.iter().enumerate() {
            text.push_str(&format!("\n[[vehicles]]\nname = \"V{i}\"\n"));
            if let Some(p) = parent {
                // p >= n names a vehicle that does not exist.
                text.push_str(&format!("parent = \"V{p}\"\nslot_m = [{x:?}, {y:?}, {z:?}]\n"));
            }
            let _ = n;
        }
        check(&text)?;
    }

    /// The key finder behind the error messages never panics, at any offset.
    #[test]
    fn key_at_never_panics(text in "\\PC{0,300}", at in any::<usize>()) {
        let _ = key_at(&text, Some(at % (text.len() + 2)));
        let _ = table_at(&text, Some(at % (text.len() + 2)));
        let _ = key_at(&text, None);
    }
}

#[test]
fn key_at_names_nested_keys() {
    let text = "name = \"x\"\n[[vehicles]]\nname = \"L\"\n[[vehicles]]\nname = \"F\"\nslot_m = [1]\n[camera]\nfov_deg = 3\n";
    let at = |needle: &str| Some(text.find(needle).unwrap());
    assert_eq!(key_at(text, at("name = \"x\"")).as_deref(), Some("name"));
    assert_eq!(
        key_at(text, at("slot_m")).as_deref(),
        Some("vehicles[1].slot_m")
    );
    assert_eq!(
        key_at(text, at("fov_deg")).as_deref(),
        Some("camera.fov_deg")
    );
    assert_eq!(table_at(text, at("slot_m")).as_deref(), Some("vehicles[1]"));
    assert_eq!(table_at(text, at("name = \"x\"")), None);
}
