//! How a judgement prints a value against its window: with the fewest decimals, from a
//! quantity's usual number, that still show the value outside the bounds as printed. A
//! fixed rounding shows a blow 3 µm past its travel window as "18.40 mm outside [18.40,
//! 18.60]", a fail that reads as a pass; a fixed 17 digits buries the figure in noise.

/// Decimals beyond which an `f64` shown in a judgement's units (mm, kN, J, a fraction)
/// carries nothing more: 17 significant digits tell any two doubles apart.
const MOST_DECIMALS: usize = 17;

/// `x` as text with `decimals` decimals.
pub fn fixed(x: f64, decimals: usize) -> String {
    format!("{x:.decimals$}")
}

/// The fewest decimals, at least `least`, with which `x` printed lies outside `[min, max]`
/// printed, read back as a reader would; `least` when `x` is inside (nothing to show).
pub fn decimals_apart(x: f64, min: f64, max: f64, least: usize) -> usize {
    if (min..=max).contains(&x) {
        return least;
    }
    let shown = |v: f64, d: usize| fixed(v, d).parse::<f64>().unwrap_or(v);
    (least..=MOST_DECIMALS)
        .find(|&d| {
            let sx = shown(x, d);
            sx > shown(max, d) || sx < shown(min, d)
        })
        .unwrap_or(MOST_DECIMALS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_value_just_past_its_window_gets_the_digits_that_show_it() {
        // The travel: 18.403 mm against [18.40, 18.402]: 2 decimals hide it, 3 show it.
        let d = decimals_apart(18.403, 18.4, 18.402, 2);
        assert_eq!(d, 3);
        assert_eq!((fixed(18.403, d), fixed(18.402, d)), ("18.403".to_string(), "18.402".to_string()));
        // Far outside: the usual digits.
        assert_eq!(decimals_apart(19.0, 18.4, 18.6, 2), 2);
        // Below the window by 0.2 µm, in mm: 4 decimals round 18.3998 apart from 18.4000.
        assert_eq!(decimals_apart(18.3998, 18.4, 18.6, 2), 4);
        // A kN load 40 N over its bound: one decimal.
        assert_eq!(decimals_apart(1200.04, 1000.0, 1200.0, 0), 2);
        assert_eq!(decimals_apart(1200.4, 1000.0, 1200.0, 0), 1);
        // Inside: nothing to show.
        assert_eq!(decimals_apart(18.5, 18.4, 18.6, 2), 2);
        // The next double past the bound still gets a number of decimals, not a loop.
        let next = f64::from_bits(18.6f64.to_bits() + 1);
        assert!(decimals_apart(next, 18.4, 18.6, 2) <= MOST_DECIMALS);
    }
}
