//! A 3×3 homography from image pixels to ground metres, in the format of
//! the ETH/UCY `H.txt` files: three lines of three numbers, row-major, so
//! that `[X Y W]ᵀ = H · [u v 1]ᵀ` and the ground point is (X/W, Y/W).
//! (For the UCY scenes the pixel origin of H is not documented — check it
//! on a known point before trusting the ground positions.)

use super::RowError;

/// A homography, row-major.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Homography(pub [[f64; 3]; 3]);

impl Homography {
    /// Parses the text of an `H.txt`; `file` names it in errors. Blank
    /// lines are ignored; anything but 3 rows of 3 finite numbers is an
    /// error at the first line that breaks the shape.
    pub fn parse(text: &str, file: &str) -> Result<Homography, RowError> {
        let mut rows: Vec<[f64; 3]> = Vec::new();
        let mut last = 0;
        for (index, raw) in text.lines().enumerate() {
            let line = index + 1;
            last = line;
            let fields: Vec<&str> = raw.split_whitespace().collect();
            if fields.is_empty() {
                continue;
            }
            if rows.len() == 3 {
                return Err(RowError::malformed(
                    file,
                    line,
                    "a homography is 3x3: this is a fourth row",
                ));
            }
            if fields.len() != 3 {
                return Err(RowError::malformed(
                    file,
                    line,
                    format!(
                        "a homography is 3x3: expected 3 numbers, got {}",
                        fields.len()
                    ),
                ));
            }
            let mut row = [0.0; 3];
            for (c, field) in fields.iter().enumerate() {
                row[c] = match field.parse::<f64>() {
                    Ok(v) if v.is_finite() => v,
                    _ => {
                        return Err(RowError::malformed(
                            file,
                            line,
                            format!("column {}: `{field}` is not a finite number", c + 1),
                        ))
                    }
                };
            }
            rows.push(row);
        }
        match rows.as_slice() {
            [a, b, c] => Ok(Homography([*a, *b, *c])),
            _ => Err(RowError::malformed(
                file,
                last + 1,
                format!("a homography is 3x3: the file has {} rows", rows.len()),
            )),
        }
    }

    /// The ground point of pixel (u, v); `None` on the horizon (W = 0).
    pub fn apply(&self, u: f64, v: f64) -> Option<(f64, f64)> {
        let h = &self.0;
        let x = h[0][0] * u + h[0][1] * v + h[0][2];
        let y = h[1][0] * u + h[1][1] * v + h[1][2];
        let w = h[2][0] * u + h[2][1] * v + h[2][2];
        (w.abs() > 1e-12).then(|| (x / w, y / w))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_an_eth_h_txt() {
        let text = "   2.8128700e-02   2.0091900e-03  -4.6693600e+00\n   8.0625700e-04   2.5195500e-02  -5.0608800e+00\n   3.4555400e-04   9.2512200e-05   4.6255300e-01\n";
        let h = Homography::parse(text, "H.txt").unwrap();
        let (x, y) = h.apply(0.0, 0.0).unwrap();
        assert!((x - -4.66936 / 0.462553).abs() < 1e-9);
        assert!((y - -5.06088 / 0.462553).abs() < 1e-9);
    }

    #[test]
    fn anything_but_3x3_is_refused_at_its_line() {
        let cases = [
            (
                "1 0 0\n0 1 0\n",
                "H.txt:3: a homography is 3x3: the file has 2 rows",
            ),
            (
                "1 0 0\n0 1\n0 0 1\n",
                "H.txt:2: a homography is 3x3: expected 3 numbers, got 2",
            ),
            (
                "1 0 0\n0 1 0\n0 0 1\n1 1 1\n",
                "H.txt:4: a homography is 3x3: this is a fourth row",
            ),
            (
                "1 0 0\n0 x 0\n0 0 1\n",
                "H.txt:2: column 2: `x` is not a finite number",
            ),
        ];
        for (text, want) in cases {
            assert_eq!(
                Homography::parse(text, "H.txt").unwrap_err().to_string(),
                want
            );
        }
        let h = Homography([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]]);
        assert_eq!(h.apply(1.0, 1.0), None);
    }
}
