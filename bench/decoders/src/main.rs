//! Each input format's decoders side by side on the same files, one thread (issue 48).
//!
//!     decoders [--rounds R] DIR|FILE ...
//!
//! Every file is read into memory once; then, for R interleaved rounds, each decoder turns every
//! file's bytes into grey pixels (8-bit stays 8-bit, 16-bit native-endian), and the median time a
//! frame of each decoder over the rounds is printed, beside a plain memory copy of the same bytes.
//! Every decoder's pixels are checked against the first decoder's, value for value (8-bit pixels
//! widened to 16 bits, as gpustar's frames hold them, equal their bytes): a decoder that differs
//! is reported and its time not counted.
//!
//! With INFLATE_ONLY set, "libdeflate + unfilter" stops after the inflate (its pixels then
//! differ, as reported): how its time splits between inflating and unfiltering.

use std::path::{Path, PathBuf};
use std::time::Instant;

type Decoded = (u32, u32, Pixels);

enum Pixels {
    U8(Vec<u8>),
    U16(Vec<u16>),
}

/// The same values, whichever width holds them.
impl PartialEq for Pixels {
    fn eq(&self, other: &Pixels) -> bool {
        let widened = |a: &[u8], b: &[u16]| {
            a.len() == b.len() && a.iter().zip(b).all(|(&x, &y)| u16::from(x) == y)
        };
        match (self, other) {
            (Pixels::U8(a), Pixels::U8(b)) => a == b,
            (Pixels::U16(a), Pixels::U16(b)) => a == b,
            (Pixels::U8(a), Pixels::U16(b)) | (Pixels::U16(b), Pixels::U8(a)) => widened(a, b),
        }
    }
}

type Decoder = fn(&[u8]) -> Result<Decoded, String>;

fn memcpy(b: &[u8]) -> Result<Decoded, String> {
    let v = b.to_vec();
    Ok((v.len() as u32, 1, Pixels::U8(v)))
}

/// A png 0.18 reader of `b`, its header read, samples as stored.
fn png_reader(b: &[u8]) -> Result<png::Reader<std::io::Cursor<&[u8]>>, String> {
    let mut d = png::Decoder::new(std::io::Cursor::new(b));
    d.set_transformations(png::Transformations::IDENTITY);
    d.read_info().map_err(|e| e.to_string())
}

fn png_crate(b: &[u8]) -> Result<Decoded, String> {
    let mut r = png_reader(b)?;
    let (w, h) = (r.info().width, r.info().height);
    let depth = r.info().bit_depth;
    let mut buf = vec![0u8; r.output_buffer_size().ok_or("size")?];
    r.next_frame(&mut buf).map_err(|e| e.to_string())?;
    Ok((w, h, png_pixels(buf, depth == png::BitDepth::Sixteen)))
}

/// png 0.18 as gpustar decoded 8-bit frames before c73465a: a frame of bytes, then widened.
fn png_frame_widened(b: &[u8]) -> Result<Decoded, String> {
    let mut r = png_reader(b)?;
    if r.info().bit_depth == png::BitDepth::Sixteen {
        return png_into_u16(b);
    }
    let (w, h) = (r.info().width, r.info().height);
    let mut buf = vec![0u8; r.output_buffer_size().ok_or("size")?];
    r.next_frame(&mut buf).map_err(|e| e.to_string())?;
    Ok((w, h, Pixels::U16(buf.into_iter().map(u16::from).collect())))
}

/// png 0.18 as gpustar decodes a frame: 16-bit samples byte-swapped in the pixels' own memory;
/// 8-bit rows widened into the pixels as they are unfiltered (since c73465a).
fn png_gpustar(b: &[u8]) -> Result<Decoded, String> {
    let mut r = png_reader(b)?;
    if r.info().bit_depth == png::BitDepth::Sixteen {
        return png_into_u16(b);
    }
    let (w, h) = (r.info().width, r.info().height);
    let mut px: Vec<u16> = Vec::with_capacity(r.output_buffer_size().ok_or("size")?);
    while let Some(row) = r.next_row().map_err(|e| e.to_string())? {
        px.extend(row.data().iter().map(|&v| u16::from(v)));
    }
    Ok((w, h, Pixels::U16(px)))
}

/// png 0.18 decoding straight into the frame's buffer: 16-bit samples byte-swapped in place,
/// 8-bit bytes left as they are.
fn png_into_u16(b: &[u8]) -> Result<Decoded, String> {
    let mut r = png_reader(b)?;
    let (w, h) = (r.info().width, r.info().height);
    let size = r.output_buffer_size().ok_or("size")?;
    if r.info().bit_depth == png::BitDepth::Sixteen {
        let mut px = vec![0u16; size / 2];
        r.next_frame(bytemuck::cast_slice_mut(&mut px))
            .map_err(|e| e.to_string())?;
        for v in &mut px {
            *v = u16::from_be(*v);
        }
        Ok((w, h, Pixels::U16(px)))
    } else {
        let mut buf = vec![0u8; size];
        r.next_frame(&mut buf).map_err(|e| e.to_string())?;
        Ok((w, h, Pixels::U8(buf)))
    }
}

fn png_pixels(buf: Vec<u8>, sixteen: bool) -> Pixels {
    if sixteen {
        Pixels::U16(
            buf.chunks_exact(2)
                .map(|b| u16::from_be_bytes([b[0], b[1]]))
                .collect(),
        )
    } else {
        Pixels::U8(buf)
    }
}

fn zune_png(b: &[u8]) -> Result<Decoded, String> {
    let mut d = zune_png::PngDecoder::new(zune_core::bytestream::ZCursor::new(b));
    let v = d.decode().map_err(|e| format!("{e:?}"))?;
    let (w, h) = d.dimensions().ok_or("no size")?;
    let px = match v {
        zune_core::result::DecodingResult::U8(v) => Pixels::U8(v),
        zune_core::result::DecodingResult::U16(v) => Pixels::U16(v),
        _ => return Err("other".into()),
    };
    Ok((w as u32, h as u32, px))
}

/// Grey 8/16-bit non-interlaced PNG: IDATs inflated by libdeflate into one buffer, then the
/// rows unfiltered in place.
fn libdeflate_png(b: &[u8]) -> Result<Decoded, String> {
    if b.len() < 8 || &b[..8] != b"\x89PNG\r\n\x1a\n" {
        return Err("not png".into());
    }
    let mut pos = 8;
    let (mut w, mut h, mut depth) = (0u32, 0u32, 0u8);
    let mut idat: Vec<&[u8]> = Vec::new();
    while pos + 8 <= b.len() {
        let n = u32::from_be_bytes(b[pos..pos + 4].try_into().unwrap()) as usize;
        let tag = &b[pos + 4..pos + 8];
        let body = b.get(pos + 8..pos + 8 + n).ok_or("short")?;
        match tag {
            b"IHDR" => {
                w = u32::from_be_bytes(body[0..4].try_into().unwrap());
                h = u32::from_be_bytes(body[4..8].try_into().unwrap());
                depth = body[8];
                if body[9] != 0 || body[12] != 0 {
                    return Err("not grey/interlaced".into());
                }
            }
            b"IDAT" => idat.push(body),
            b"IEND" => break,
            _ => {}
        }
        pos += 12 + n;
    }
    // One IDAT is inflated where it lies; several are joined first.
    let joined;
    let z = if let [one] = idat[..] {
        one
    } else {
        joined = idat.concat();
        &joined
    };
    let bpp = (depth / 8) as usize;
    let stride = w as usize * bpp;
    let mut raw = vec![0u8; (stride + 1) * h as usize];
    let mut dec = libdeflater::Decompressor::new();
    dec.zlib_decompress(z, &mut raw)
        .map_err(|e| e.to_string())?;
    if std::env::var_os("INFLATE_ONLY").is_some() {
        return Ok((w, h, png_pixels(raw, bpp == 2)));
    }
    let mut out = vec![0u8; stride * h as usize];
    unfilter(&raw, &mut out, stride, bpp)?;
    Ok((w, h, png_pixels(out, bpp == 2)))
}

fn unfilter(raw: &[u8], out: &mut [u8], stride: usize, bpp: usize) -> Result<(), String> {
    let zero = vec![0u8; stride];
    for i in 0..out.len() / stride {
        let row = &raw[i * (stride + 1)..(i + 1) * (stride + 1)];
        let (f, line) = (row[0], &row[1..]);
        let (done, rest) = out.split_at_mut(i * stride);
        let up: &[u8] = if i == 0 {
            &zero
        } else {
            &done[(i - 1) * stride..]
        };
        let cur = &mut rest[..stride];
        match f {
            0 => cur.copy_from_slice(line),
            1 => {
                cur[..bpp].copy_from_slice(&line[..bpp]);
                for x in bpp..stride {
                    cur[x] = line[x].wrapping_add(cur[x - bpp]);
                }
            }
            2 => {
                for x in 0..stride {
                    cur[x] = line[x].wrapping_add(up[x]);
                }
            }
            3 => {
                for x in 0..bpp {
                    cur[x] = line[x].wrapping_add(up[x] >> 1);
                }
                for x in bpp..stride {
                    let a = cur[x - bpp] as u16;
                    cur[x] = line[x].wrapping_add(((a + up[x] as u16) >> 1) as u8);
                }
            }
            4 => {
                for x in 0..bpp {
                    cur[x] = line[x].wrapping_add(up[x]);
                }
                for x in bpp..stride {
                    let (a, b, c) = (cur[x - bpp] as i16, up[x] as i16, up[x - bpp] as i16);
                    let p = a + b - c;
                    let (pa, pb, pc) = ((p - a).abs(), (p - b).abs(), (p - c).abs());
                    let pred = if pa <= pb && pa <= pc {
                        a
                    } else if pb <= pc {
                        b
                    } else {
                        c
                    };
                    cur[x] = line[x].wrapping_add(pred as u8);
                }
            }
            _ => return Err(format!("filter {f}")),
        }
    }
    Ok(())
}

fn image_crate(b: &[u8]) -> Result<Decoded, String> {
    let img = image::ImageReader::new(std::io::Cursor::new(b))
        .with_guessed_format()
        .map_err(|e| e.to_string())?
        .decode()
        .map_err(|e| e.to_string())?;
    let (w, h) = (img.width(), img.height());
    Ok(match img {
        image::DynamicImage::ImageLuma8(v) => (w, h, Pixels::U8(v.into_raw())),
        image::DynamicImage::ImageLuma16(v) => (w, h, Pixels::U16(v.into_raw())),
        other => (w, h, Pixels::U8(other.to_luma8().into_raw())),
    })
}

/// zune-jpeg straight to luma: a colour JPEG's Y plane, no chroma upsampling or conversion.
fn zune_jpeg_luma(b: &[u8]) -> Result<Decoded, String> {
    let opts = zune_core::options::DecoderOptions::default()
        .jpeg_set_out_colorspace(zune_core::colorspace::ColorSpace::Luma);
    let mut d =
        zune_jpeg::JpegDecoder::new_with_options(zune_core::bytestream::ZCursor::new(b), opts);
    let v = d.decode().map_err(|e| format!("{e:?}"))?;
    let (w, h) = d.dimensions().ok_or("no size")?;
    Ok((w as u32, h as u32, Pixels::U8(v)))
}

/// The `tiff` crate straight, without `image` around it.
fn tiff_crate(b: &[u8]) -> Result<Decoded, String> {
    let mut d = tiff::decoder::Decoder::new(std::io::Cursor::new(b)).map_err(|e| e.to_string())?;
    let (w, h) = d.dimensions().map_err(|e| e.to_string())?;
    Ok(match d.read_image().map_err(|e| e.to_string())? {
        tiff::decoder::DecodingResult::U8(v) => (w, h, Pixels::U8(v)),
        tiff::decoder::DecodingResult::U16(v) => (w, h, Pixels::U16(v)),
        _ => return Err("other sample type".into()),
    })
}

fn files(args: &[String]) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for a in args {
        let p = Path::new(a);
        if p.is_dir() {
            let mut v: Vec<PathBuf> = std::fs::read_dir(p)
                .unwrap()
                .map(|e| e.unwrap().path())
                .filter(|p| {
                    let e = p
                        .extension()
                        .and_then(|e| e.to_str())
                        .unwrap_or("")
                        .to_lowercase();
                    matches!(e.as_str(), "png" | "jpg" | "jpeg" | "tif" | "tiff")
                })
                .collect();
            v.sort();
            out.extend(v);
        } else {
            out.push(p.to_path_buf());
        }
    }
    out
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let mut rounds = 5;
    if args.first().map(|s| s.as_str()) == Some("--rounds") {
        rounds = args[1].parse().unwrap();
        args.drain(..2);
    }
    let paths = files(&args);
    let data: Vec<Vec<u8>> = paths.iter().map(|p| std::fs::read(p).unwrap()).collect();
    let is_png = data[0].starts_with(b"\x89PNG");
    let decoders: Vec<(&str, Decoder)> = if is_png {
        vec![
            ("png 0.18, bytes converted", png_crate),
            ("png 0.18 into the pixels, 8-bit unwidened", png_into_u16),
            ("png 0.18, gpustar's path (8-bit widened)", png_gpustar),
            ("png 0.18, gpustar's path before c73465a", png_frame_widened),
            ("image 0.25", image_crate),
            ("zune-png 0.5", zune_png),
            ("libdeflate + unfilter", libdeflate_png),
            ("memory copy", memcpy),
        ]
    } else if data[0].starts_with(&[0xFF, 0xD8]) {
        vec![
            ("image 0.25 (zune-jpeg, gpustar today)", image_crate),
            ("zune-jpeg 0.5, luma out", zune_jpeg_luma),
            ("memory copy", memcpy),
        ]
    } else {
        vec![
            ("image 0.25 (gpustar today)", image_crate),
            ("tiff 0.11", tiff_crate),
            ("memory copy", memcpy),
        ]
    };
    let reference: Vec<Decoded> = data.iter().map(|b| decoders[0].1(b).unwrap()).collect();
    let mut ok = vec![true; decoders.len()];
    let mut times = vec![Vec::new(); decoders.len()];
    for _ in 0..rounds {
        for (k, (name, dec)) in decoders.iter().enumerate() {
            let t = Instant::now();
            for (i, b) in data.iter().enumerate() {
                match dec(b) {
                    Ok(d) => {
                        if *name != "memory copy" && d != reference[i] {
                            ok[k] = false;
                        }
                    }
                    Err(e) => {
                        eprintln!("{name}: {}: {e}", paths[i].display());
                        ok[k] = false;
                    }
                }
            }
            times[k].push(t.elapsed().as_secs_f64() * 1e3 / data.len() as f64);
        }
    }
    let bytes: f64 = data.iter().map(|b| b.len() as f64).sum::<f64>() / data.len() as f64;
    let (w, h, px) = &reference[0];
    let depth = if matches!(px, Pixels::U8(_)) { 8 } else { 16 };
    println!(
        "{} files, {w}x{h} {depth}-bit, {:.0} kB a file; median of {rounds} rounds, ms a frame",
        data.len(),
        bytes / 1e3
    );
    for (k, (name, _)) in decoders.iter().enumerate() {
        let same = if *name == "memory copy" {
            "(file bytes)"
        } else if ok[k] {
            "same pixels"
        } else {
            "DIFFERENT or failed"
        };
        println!("  {name:44} {:7.3} ms  {same}", median(times[k].clone()));
    }
}
