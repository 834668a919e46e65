use std::time::Instant;
fn main() {
    let path = std::env::args().nth(1).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let n = 50;
    let t = Instant::now();
    for _ in 0..n {
        std::hint::black_box(image::load_from_memory(&bytes).unwrap());
    }
    println!(
        "image::load_from_memory {:.2} ms",
        t.elapsed().as_secs_f64() * 1e3 / n as f64
    );
    let t = Instant::now();
    for _ in 0..n {
        std::hint::black_box(gpustar::io::frame::Frame::read(std::path::Path::new(&path)).unwrap());
    }
    println!(
        "Frame::read {:.2} ms",
        t.elapsed().as_secs_f64() * 1e3 / n as f64
    );
    let img = image::load_from_memory(&bytes).unwrap().to_luma8();
    for (name, c, f) in [
        (
            "fast+sub",
            image::codecs::png::CompressionType::Fast,
            image::codecs::png::FilterType::Sub,
        ),
        (
            "default+nofilter",
            image::codecs::png::CompressionType::Default,
            image::codecs::png::FilterType::NoFilter,
        ),
        (
            "fast+adaptive",
            image::codecs::png::CompressionType::Fast,
            image::codecs::png::FilterType::Adaptive,
        ),
        (
            "best+adaptive",
            image::codecs::png::CompressionType::Best,
            image::codecs::png::FilterType::Adaptive,
        ),
    ] {
        let mut out = Vec::new();
        image::codecs::png::PngEncoder::new_with_quality(&mut out, c, f)
            .write_image(
                img.as_raw(),
                img.width(),
                img.height(),
                image::ExtendedColorType::L8,
            )
            .unwrap();
        let t = Instant::now();
        for _ in 0..n {
            std::hint::black_box(image::load_from_memory(&out).unwrap());
        }
        println!(
            "{name}: {} KB, decode {:.2} ms",
            out.len() / 1024,
            t.elapsed().as_secs_f64() * 1e3 / n as f64
        );
    }
}
use image::ImageEncoder;
