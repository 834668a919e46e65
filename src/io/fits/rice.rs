//! The Rice decoder of tile-compressed FITS (RICE_1), after CFITSIO's `fits_rdecomp` and its
//! short and byte forms.

/// Bits read from the most significant end, as the Rice coder writes them.
struct Bits<'a> {
    data: &'a [u8],
    pos: usize,
    acc: u64,
    /// Valid bits in the low end of `acc`.
    n: u32,
}

impl Bits<'_> {
    fn refill(&mut self) {
        while self.n <= 56 && self.pos < self.data.len() {
            self.acc = (self.acc << 8) | self.data[self.pos] as u64;
            self.pos += 1;
            self.n += 8;
        }
    }

    fn mask(n: u32) -> u64 {
        if n == 0 { 0 } else { u64::MAX >> (64 - n) }
    }

    /// The next `k` (at most 32) bits.
    fn read(&mut self, k: u32) -> Option<u64> {
        if k == 0 {
            return Some(0);
        }
        self.refill();
        if self.n < k {
            return None;
        }
        self.n -= k;
        let v = (self.acc >> self.n) & Self::mask(k);
        self.acc &= Self::mask(self.n);
        Some(v)
    }

    /// The number of 0 bits before the next 1 bit, which is read too.
    fn zeros(&mut self) -> Option<u64> {
        let mut z = 0u64;
        loop {
            self.refill();
            if self.n == 0 || z > 64 {
                return None;
            }
            if self.acc == 0 {
                z += self.n as u64;
                self.n = 0;
                continue;
            }
            let top = self.n - 1 - self.acc.ilog2();
            z += top as u64;
            self.n -= top + 1;
            self.acc &= Self::mask(self.n);
            return Some(z);
        }
    }
}

/// Decode `n` Rice-coded values of `bytepix` bytes (CFITSIO's fits_rdecomp and its short and
/// byte forms): the first value verbatim, then blocks of `block` differences, each block with
/// its split `fs` (or all zero, or verbatim). Values wrap modulo 2^(8·bytepix) and are read as
/// the signed type of that width (unsigned for bytes). None on corrupt or short data.
pub(crate) fn rice(packed: &[u8], n: usize, bytepix: usize, block: usize) -> Option<Vec<i64>> {
    let (fs_bits, fs_max, bits) = match bytepix {
        1 => (3, 6, 8),
        2 => (4, 14, 16),
        _ => (5, 25, 32),
    };
    let wrap = Bits::mask(bits);
    let first = packed.get(..bytepix)?;
    let mut last = first.iter().fold(0u64, |a, &b| (a << 8) | b as u64);
    let mut r = Bits {
        data: &packed[bytepix..],
        pos: 0,
        acc: 0,
        n: 0,
    };
    let mut out = Vec::with_capacity(n);
    let unmap = |d: u64| if d & 1 == 0 { d >> 1 } else { !(d >> 1) & wrap };
    while out.len() < n {
        let fs = r.read(fs_bits)? as i64 - 1;
        let end = (out.len() + block).min(n);
        while out.len() < end {
            if fs >= 0 {
                let d = if fs == fs_max {
                    r.read(bits)?
                } else {
                    let z = r.zeros()?;
                    (z << fs) | r.read(fs as u32)?
                };
                last = (unmap(d).wrapping_add(last)) & wrap;
            }
            out.push(last);
        }
    }
    Some(
        out.into_iter()
            .map(|v| match bytepix {
                1 => v as i64,
                2 => v as u16 as i16 as i64,
                _ => v as u32 as i32 as i64,
            })
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rice_reads_a_hand_made_stream() {
        // bytepix 2 (4-bit fs codes), block 4: the first value 100, then a block with fs = 1
        // (code 0010) of the differences +1, -1, 0, +2, mapped to 2, 1, 0, 4 and each written
        // as d >> 1 zeros, a one, and d's low bit; then a block of code 0000 (all equal).
        let bits = "0010".to_string() + "010" + "11" + "10" + "0010" + "0000";
        let mut bytes = vec![0x00, 0x64];
        let padded = format!("{bits:0<32}");
        for c in padded.as_bytes().chunks(8) {
            bytes.push(u8::from_str_radix(std::str::from_utf8(c).unwrap(), 2).unwrap());
        }
        assert_eq!(rice(&bytes, 5, 2, 4), Some(vec![101, 100, 100, 102, 102]));
        // Cut short: None, not a panic.
        assert_eq!(rice(&bytes[..3], 5, 2, 4), None);
        assert_eq!(rice(&[], 5, 2, 4), None);
    }
}
