//! "Did you mean …?" suggestions for unknown names, functors and keywords.

/// The candidate closest to `name`, if one is close enough to be a likely typo.
///
/// A candidate equal to `name` ignoring case wins outright. Otherwise the
/// closest candidate by Damerau-Levenshtein distance (ignoring case) is taken
/// when the distance is at most a third of the name's length (at least 1, and
/// less than the length, so one-letter names get no suggestion). Ties go to the
/// alphabetically first candidate, so the answer does not depend on the order
/// of `candidates` (often a hash map's).
pub fn did_you_mean<'a>(
    name: &str,
    candidates: impl IntoIterator<Item = &'a str>,
) -> Option<&'a str> {
    let name_chars = name.chars().count();
    let lowercase_name = name.to_lowercase();
    let allowed_distance = (name_chars.max(3) / 3).min(name_chars.saturating_sub(1));
    let mut best: Option<(usize, &'a str)> = None;
    for candidate in candidates {
        // Equal ignoring case is distance 0, which no other candidate beats.
        let distance = strsim::damerau_levenshtein(&lowercase_name, &candidate.to_lowercase());
        if distance > allowed_distance {
            continue;
        }
        let better = match best {
            None => true,
            Some((best_distance, best_candidate)) => {
                (distance, candidate) < (best_distance, best_candidate)
            }
        };
        if better {
            best = Some((distance, candidate));
        }
    }
    best.map(|(_, candidate)| candidate)
}

#[cfg(test)]
mod tests {
    use super::did_you_mean;

    const FUNCTORS: [&str; 6] = ["intersect", "occluded", "occRayGen", "shader", "add", "and"];

    #[test]
    fn suggestions() {
        let cases = [
            ("intersct", Some("intersect")),
            ("intresect", Some("intersect")),
            ("occrayGen", Some("occRayGen")),
            ("OCCLUDED", Some("occluded")),
            ("shadr", Some("shader")),
            ("ad", Some("add")), // `and` is as close; ties go alphabetically
            ("a", None),
            ("x", None),
            ("reflect", None),
            ("", None),
        ];
        for (name, expected) in cases {
            assert_eq!(did_you_mean(name, FUNCTORS), expected, "for `{name}`");
        }
    }
}
