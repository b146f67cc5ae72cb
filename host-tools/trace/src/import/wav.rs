//! Multi-channel WAV from a sound-card recorder (hound reads it): channel k
//! is named `k` (from 1); a sample is a fraction of full scale (an integer
//! divided by 2^(bits−1), a float as written), times the `scale` the map
//! gives that channel (its reading at full scale, in the channel's unit).

use crate::import::columns::{find, Channel};
use crate::import::mapping::ImportMap;

/// Whether `head` starts a WAV file.
pub fn is_wav(head: &[u8]) -> bool {
    head.len() >= 12 && &head[0..4] == b"RIFF" && &head[8..12] == b"WAVE"
}

/// The channels scaled by the map, and the sample rate from the header.
pub fn read(bytes: &[u8], map: &ImportMap) -> Result<(Vec<Channel>, f64), String> {
    let mut r = hound::WavReader::new(std::io::Cursor::new(bytes)).map_err(|e| format!("WAV: {e}"))?;
    let spec = r.spec();
    let n = spec.channels as usize;
    if n == 0 || spec.sample_rate == 0 {
        return Err("WAV header: no channels or a sample rate of 0".into());
    }
    let mut values: Vec<Vec<f64>> = vec![Vec::new(); n];
    match spec.sample_format {
        hound::SampleFormat::Float => {
            for (i, s) in r.samples::<f32>().enumerate() {
                values[i % n].push(s.map_err(|e| format!("WAV sample {}: {e}", i / n + 1))? as f64);
            }
        }
        hound::SampleFormat::Int => {
            let full = (1u64 << (spec.bits_per_sample.clamp(1, 32) - 1)) as f64;
            for (i, s) in r.samples::<i32>().enumerate() {
                values[i % n].push(s.map_err(|e| format!("WAV sample {}: {e}", i / n + 1))? as f64 / full);
            }
        }
    }
    if values.iter().any(|v| v.len() != values[0].len()) {
        return Err("WAV: the data ends inside a sample frame".into());
    }
    let mut channels: Vec<Channel> = values
        .into_iter()
        .enumerate()
        .map(|(k, v)| Channel::new((k + 1).to_string(), v))
        .collect();
    for key in ["p_rear", "p_front", "accel"] {
        let r = map.resolve(key).map_err(|e| e.to_string())?;
        let Some(i) = find(&channels, &r.column, key)? else {
            return Err(format!(
                "no channel {} for {key}: a WAV file has channels 1 ..= {n}; map each ([import.{key}] column = 1, scale = ...)",
                r.column
            ));
        };
        let scale = r.scale.ok_or_else(|| {
            format!("[import.{key}] scale: a WAV sample is a fraction of full scale; give the reading at full scale (in {})", r.unit)
        })?;
        for v in channels[i].values.iter_mut() {
            *v *= scale;
        }
    }
    Ok((channels, spec.sample_rate as f64))
}
