//! The recorders' file readers (`hammer_trace::import`) on arbitrary bytes:
//! the first byte picks the format (delimited text with a mapping, TDMS,
//! MAT v5, WAV, Parquet), the rest is the file. Invariants: no panic; an
//! accepted file gives a consistent trace (columns of one length, a
//! positive period, finite values); a refusal is a typed error.

use std::io::Cursor;

use hammer_trace::import::mapping::{ColumnRef, ImportMap, Signal};
use hammer_trace::import::{collect, open_from, Format};
use hammer_trace::rows::Uniform;

use super::{bit, Target};

pub const TARGET: Target = Target {
    name: "import",
    run,
    dict: &[
        b"TDSm",
        b"MATLAB 5.0 MAT-file",
        b"IM",
        b"RIFF",
        b"WAVE",
        b"fmt ",
        b"data",
        b"PAR1",
        b"/'bench'/'p_rear_pa'",
        b"wf_increment",
        b";",
        b",",
        b"\n",
        b"\xff\xff\xff\xff",
        b"\x00\x00\x00\x00",
        b"\x0e\x00\x00\x00",
        b"\x09\x00\x00\x00",
        b"\"",
        b"\"\"",
        b"meta.a",
    ],
    seeds,
};

const FORMATS: [Format; 5] = [
    Format::Delimited,
    Format::Tdms,
    Format::Mat,
    Format::Wav,
    Format::Parquet,
];

/// A recorder's text layout and a WAV's channels, as a user would map them.
fn map(format: Format) -> ImportMap {
    let sig = |col: ColumnRef, unit: &str, scale: Option<f64>| Signal {
        column: Some(col),
        unit: Some(unit.into()),
        scale,
        ..Signal::default()
    };
    match format {
        Format::Delimited => ImportMap {
            decimal: Some(",".into()),
            t: Some(sig(ColumnRef::Name("ms".into()), "ms", None)),
            p_rear: Some(sig(ColumnRef::Name("rear".into()), "bar", None)),
            p_front: Some(sig(ColumnRef::Index(3), "bar", None)),
            accel: Some(sig(ColumnRef::Name("a".into()), "g", None)),
            ..ImportMap::default()
        },
        Format::Wav => ImportMap {
            p_rear: Some(sig(ColumnRef::Index(1), "bar", Some(10.0))),
            p_front: Some(sig(ColumnRef::Index(2), "bar", Some(10.0))),
            accel: Some(sig(ColumnRef::Index(3), "g", Some(200.0))),
            ..ImportMap::default()
        },
        _ => ImportMap::default(),
    }
}

fn run(data: &[u8]) -> u64 {
    let Some((&k, file)) = data.split_first() else {
        return bit(0);
    };
    let format = FORMATS[k as usize % FORMATS.len()];
    let m = map(format);
    let base = 1 + 8 * (k as u32 % FORMATS.len() as u32);
    let opened = match open_from(Cursor::new(file.to_vec()), "fuzz", format, Some(&m), false) {
        Ok(o) => o,
        Err(_) => return bit(base),
    };
    let trace = match Uniform::new(opened.source).and_then(|u| collect(u, Vec::new())) {
        Ok(t) => t,
        Err(_) => return bit(base + 1),
    };
    let n = trace.len();
    assert!(n >= 2);
    assert!(trace.dt_s > 0.0, "a positive period");
    for col in [&trace.t_s, &trace.p_rear_pa, &trace.p_front_pa, &trace.accel_mps2] {
        assert_eq!(col.len(), n);
        assert!(col.iter().all(|v| v.is_finite()));
    }
    bit(base + 2 + trace.gaps.len().min(2) as u32)
}

/// A TDMS file of one segment: `channels` under group `bench`, each with
/// `wf_increment`; interleaved or not.
pub fn tdms(channels: &[(&str, Vec<f64>)], interleaved: bool) -> Vec<u8> {
    let mut meta = Vec::new();
    let s = |m: &mut Vec<u8>, t: &str| {
        m.extend_from_slice(&(t.len() as u32).to_le_bytes());
        m.extend_from_slice(t.as_bytes());
    };
    meta.extend_from_slice(&(channels.len() as u32).to_le_bytes());
    for (name, v) in channels {
        s(&mut meta, &format!("/'bench'/'{name}'"));
        meta.extend_from_slice(&20u32.to_le_bytes());
        meta.extend_from_slice(&10u32.to_le_bytes());
        meta.extend_from_slice(&1u32.to_le_bytes());
        meta.extend_from_slice(&(v.len() as u64).to_le_bytes());
        meta.extend_from_slice(&1u32.to_le_bytes());
        s(&mut meta, "wf_increment");
        meta.extend_from_slice(&10u32.to_le_bytes());
        meta.extend_from_slice(&1e-5f64.to_le_bytes());
    }
    let mut raw = Vec::new();
    let n = channels.first().map_or(0, |c| c.1.len());
    if interleaved {
        for i in 0..n {
            for (_, v) in channels {
                raw.extend_from_slice(&v[i].to_le_bytes());
            }
        }
    } else {
        for (_, v) in channels {
            for x in v {
                raw.extend_from_slice(&x.to_le_bytes());
            }
        }
    }
    let toc: u32 = (1 << 1) | (1 << 2) | (1 << 3) | if interleaved { 1 << 5 } else { 0 };
    let mut out = b"TDSm".to_vec();
    out.extend_from_slice(&toc.to_le_bytes());
    out.extend_from_slice(&4713u32.to_le_bytes());
    out.extend_from_slice(&((meta.len() + raw.len()) as u64).to_le_bytes());
    out.extend_from_slice(&(meta.len() as u64).to_le_bytes());
    out.extend(meta);
    out.extend(raw);
    out
}

/// A MAT v5 file of double vectors, uncompressed.
pub fn mat(vars: &[(&str, Vec<f64>)]) -> Vec<u8> {
    let mut out = vec![b' '; 128];
    out[..19].copy_from_slice(b"MATLAB 5.0 MAT-file");
    out[124..128].copy_from_slice(&[0, 1, b'I', b'M']);
    let el = |o: &mut Vec<u8>, ty: u32, data: &[u8]| {
        o.extend_from_slice(&ty.to_le_bytes());
        o.extend_from_slice(&(data.len() as u32).to_le_bytes());
        o.extend_from_slice(data);
        o.resize(o.len().div_ceil(8) * 8, 0);
    };
    for (name, v) in vars {
        let mut m = Vec::new();
        el(&mut m, 6, &[6, 0, 0, 0, 0, 0, 0, 0]);
        let dims: Vec<u8> = [1i32, v.len() as i32].iter().flat_map(|d| d.to_le_bytes()).collect();
        el(&mut m, 5, &dims);
        el(&mut m, 1, name.as_bytes());
        let data: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
        el(&mut m, 9, &data);
        el(&mut out, 14, &m);
    }
    out
}

/// A 3-channel 16-bit WAV at 100 kS/s.
fn wav(frames: &[[i16; 3]]) -> Vec<u8> {
    let mut out = b"RIFF".to_vec();
    let data_len = (frames.len() * 6) as u32;
    out.extend_from_slice(&(36 + data_len).to_le_bytes());
    out.extend_from_slice(b"WAVEfmt ");
    out.extend_from_slice(&16u32.to_le_bytes());
    out.extend_from_slice(&1u16.to_le_bytes());
    out.extend_from_slice(&3u16.to_le_bytes());
    out.extend_from_slice(&100_000u32.to_le_bytes());
    out.extend_from_slice(&600_000u32.to_le_bytes());
    out.extend_from_slice(&6u16.to_le_bytes());
    out.extend_from_slice(&16u16.to_le_bytes());
    out.extend_from_slice(b"data");
    out.extend_from_slice(&data_len.to_le_bytes());
    for f in frames {
        for s in f {
            out.extend_from_slice(&s.to_le_bytes());
        }
    }
    out
}

/// A Parquet file of `t_s` and the channels, Snappy-compressed.
fn parquet(channels: &[(&str, Vec<f64>)], t: &[f64]) -> Vec<u8> {
    use parquet::basic::Compression;
    use parquet::data_type::DoubleType;
    use parquet::file::properties::WriterProperties;
    use parquet::file::writer::SerializedFileWriter;
    use std::sync::Arc;
    let mut schema = String::from("message seed {\n  REQUIRED DOUBLE t_s;\n");
    for (n, _) in channels {
        schema.push_str(&format!("  REQUIRED DOUBLE {n};\n"));
    }
    schema.push('}');
    let schema = Arc::new(parquet::schema::parser::parse_message_type(&schema).expect("a valid schema"));
    let props = Arc::new(WriterProperties::builder().set_compression(Compression::SNAPPY).build());
    let mut out = Vec::new();
    let mut w = SerializedFileWriter::new(&mut out, schema, props).expect("a writer");
    let mut g = w.next_row_group().expect("a row group");
    let mut k = 0;
    while let Some(mut col) = g.next_column().expect("a column") {
        let v = if k == 0 { t } else { &channels[k - 1].1[..] };
        col.typed::<DoubleType>().write_batch(v, None, None).expect("written");
        col.close().expect("closed");
        k += 1;
    }
    g.close().expect("closed");
    w.close().expect("closed");
    out
}

/// A Parquet file as pyarrow writes a table with a struct column between
/// the signals (`t_s, p_rear_pa, p_front_pa, meta{a, b}, accel_mps2,
/// accel_b_mps2`), `meta.b` nullable with every third value null: the
/// layout that once shifted later columns under other names.
fn nested_parquet(channels: &[(&str, Vec<f64>)], t: &[f64]) -> Vec<u8> {
    use parquet::basic::Compression;
    use parquet::data_type::DoubleType;
    use parquet::file::properties::WriterProperties;
    use parquet::file::writer::SerializedFileWriter;
    use std::sync::Arc;
    let schema =
        "message seed {\n  REQUIRED DOUBLE t_s;\n  REQUIRED DOUBLE p_rear_pa;\n  REQUIRED DOUBLE p_front_pa;\n  \
                  REQUIRED group meta {\n    REQUIRED DOUBLE a;\n    OPTIONAL DOUBLE b;\n  }\n  \
                  REQUIRED DOUBLE accel_mps2;\n  REQUIRED DOUBLE accel_b_mps2;\n}";
    let schema = Arc::new(parquet::schema::parser::parse_message_type(schema).expect("a valid schema"));
    let props = Arc::new(WriterProperties::builder().set_compression(Compression::SNAPPY).build());
    let n = t.len();
    let meta_a: Vec<f64> = (0..n).map(|i| i as f64).collect();
    let defs: Vec<i16> = (0..n).map(|i| i16::from(i % 3 != 0)).collect();
    let meta_b: Vec<f64> = (0..n).filter(|i| i % 3 != 0).map(|i| i as f64 * 0.5).collect();
    let accel_b: Vec<f64> = channels[2].1.iter().map(|a| -3.0 * a).collect();
    let leaves: [(&[f64], Option<&[i16]>); 7] = [
        (t, None),
        (&channels[0].1, None),
        (&channels[1].1, None),
        (&meta_a, None),
        (&meta_b, Some(&defs)),
        (&channels[2].1, None),
        (&accel_b, None),
    ];
    let mut out = Vec::new();
    let mut w = SerializedFileWriter::new(&mut out, schema, props).expect("a writer");
    let mut g = w.next_row_group().expect("a row group");
    let mut k = 0;
    while let Some(mut col) = g.next_column().expect("a column") {
        let (v, d) = leaves[k];
        col.typed::<DoubleType>().write_batch(v, d, None).expect("written");
        col.close().expect("closed");
        k += 1;
    }
    g.close().expect("closed");
    w.close().expect("closed");
    out
}

fn seeds() -> Vec<Vec<u8>> {
    let n = 24;
    let p: Vec<f64> = (0..n).map(|i| 1e5 * (i as f64 * 0.3).sin()).collect();
    let a: Vec<f64> = (0..n).map(|i| 50.0 * (i as f64 * 0.7).cos()).collect();
    let t: Vec<f64> = (0..n).map(|i| i as f64 * 1e-5).collect();
    let chans = [
        ("p_rear_pa", p.clone()),
        ("p_front_pa", p.clone()),
        ("accel_mps2", a.clone()),
    ];
    let with = |k: u8, body: Vec<u8>| {
        let mut v = vec![k];
        v.extend(body);
        v
    };
    let mut text = String::from("recorder 1\nms;rear;front;a\n");
    for i in 0..n {
        text.push_str(&format!("{};{};{};{}\n", i as f64 * 0.01, p[i] / 1e5, p[i] / 1e5, a[i] / 9.8).replace('.', ","));
    }
    // pandas' `to_csv(decimal=",")` under `,`: every number quoted, one with an escaped quote.
    let mut quoted = String::from("ms,rear,\"front \"\"B\"\"\",a\n");
    for i in 0..n {
        let f = |x: f64| format!("\"{x}\"").replace('.', ",");
        quoted.push_str(&format!(
            "{},{},{},{}\n",
            f(i as f64 * 0.01),
            f(p[i] / 1e5),
            f(p[i] / 1e5),
            f(a[i] / 9.8)
        ));
    }
    let frames: Vec<[i16; 3]> = (0..n)
        .map(|i| {
            [
                (p[i] / 1e6 * 32767.0) as i16,
                (p[i] / 2e6 * 32767.0) as i16,
                (a[i] / 2000.0 * 32767.0) as i16,
            ]
        })
        .collect();
    let mut mat_vars = vec![("t_s", t)];
    mat_vars.extend(chans.iter().map(|(n, v)| (*n, v.clone())));
    vec![
        with(0, text.into_bytes()),
        with(1, tdms(&chans, false)),
        with(1, tdms(&chans, true)),
        with(2, mat(&mat_vars)),
        with(3, wav(&frames)),
        with(4, parquet(&chans, &mat_vars[0].1)),
        with(0, quoted.into_bytes()),
        with(4, nested_parquet(&chans, &mat_vars[0].1)),
    ]
}
