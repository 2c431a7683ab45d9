//! The parsers never panic: header and first records of the shipped ESBC files, mutated
//! (bytes replaced, lines cut, deleted or doubled, text truncated), give either a file or an
//! error.

use proptest::prelude::*;
use sextant_rinex::{parse_navigation, parse_observation, read_text};
use std::path::Path;
use std::sync::OnceLock;

fn head(file: &str, lines_after_header: usize) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/data/rinex-esbc")
        .join(file);
    let text = read_text(&path).unwrap();
    let end = text.find("END OF HEADER").unwrap();
    let body_start = end + text[end..].find('\n').unwrap() + 1;
    let body: String = text[body_start..]
        .lines()
        .take(lines_after_header)
        .flat_map(|l| [l, "\n"])
        .collect();
    format!("{}{}", &text[..body_start], body)
}

fn obs_seed() -> &'static str {
    static S: OnceLock<String> = OnceLock::new();
    // The header and the first two epochs (43 satellites each).
    S.get_or_init(|| head("ESBC00DNK_R_20201770000_01H_30S_MO.rnx.gz", 88))
}

fn nav_seed() -> &'static str {
    static S: OnceLock<String> = OnceLock::new();
    S.get_or_init(|| head("ESBC00DNK_R_20201770000_01D_GN.rnx.gz", 32))
}

#[derive(Debug, Clone)]
enum Mutation {
    Replace(usize, char),
    Truncate(usize),
    CutLine(usize, usize),
    DeleteLine(usize),
    DoubleLine(usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    let chars = prop::sample::select(vec![
        '0', '9', '.', '-', '+', ' ', 'x', 'D', 'e', '\n', '>', 'G', 'R', 'é', '\u{0}',
    ]);
    prop_oneof![
        (any::<usize>(), chars).prop_map(|(i, c)| Mutation::Replace(i, c)),
        any::<usize>().prop_map(Mutation::Truncate),
        (any::<usize>(), 0usize..80).prop_map(|(i, n)| Mutation::CutLine(i, n)),
        any::<usize>().prop_map(Mutation::DeleteLine),
        any::<usize>().prop_map(Mutation::DoubleLine),
    ]
}

fn apply(text: &str, muts: &[Mutation]) -> String {
    let mut t = text.to_string();
    for m in muts {
        let mut lines: Vec<String> = t.lines().map(str::to_string).collect();
        if lines.is_empty() {
            break;
        }
        let nl = lines.len();
        match *m {
            Mutation::Replace(i, c) => {
                let b: Vec<char> = t.chars().collect();
                let i = i % b.len().max(1);
                t = b
                    .iter()
                    .enumerate()
                    .map(|(k, &x)| if k == i { c } else { x })
                    .collect();
                continue;
            }
            Mutation::Truncate(i) => {
                let b: Vec<char> = t.chars().collect();
                t = b[..i % (b.len() + 1)].iter().collect();
                continue;
            }
            Mutation::CutLine(i, n) => {
                let l = &mut lines[i % nl];
                let keep: String = l.chars().take(n).collect();
                *l = keep;
            }
            Mutation::DeleteLine(i) => {
                lines.remove(i % nl);
            }
            Mutation::DoubleLine(i) => {
                let l = lines[i % nl].clone();
                lines.insert(i % nl, l);
            }
        }
        t = lines.join("\n");
    }
    t
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    #[test]
    fn observation_parser_never_panics(muts in prop::collection::vec(mutation(), 1..6)) {
        let _ = parse_observation(&apply(obs_seed(), &muts));
    }

    #[test]
    fn navigation_parser_never_panics(muts in prop::collection::vec(mutation(), 1..6)) {
        let _ = parse_navigation(&apply(nav_seed(), &muts));
    }
}

#[test]
fn seeds_parse() {
    let o = parse_observation(obs_seed()).unwrap();
    assert_eq!(o.epochs.len(), 2);
    let n = parse_navigation(nav_seed()).unwrap();
    assert_eq!(n.gps.len(), 4);
}
