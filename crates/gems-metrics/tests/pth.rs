//! Loading LPIPS weights from PyTorch checkpoints in both the zip and the legacy stream format,
//! written here from the random reference weights (lpips `alex.pth` layout for the heads,
//! torchvision `features.N.*` layout for the backbone).

mod common;

use std::io::Write;

use gems_metrics::Lpips;

struct Entry {
    name: String,
    shape: Vec<usize>,
    data: Vec<u8>,
}

fn weights() -> Vec<Entry> {
    let bytes = std::fs::read(common::LPIPS_WEIGHTS).unwrap();
    let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let rename = |n: &str| {
        for (lp, tv) in [
            ("net.slice1.0.", "features.0."),
            ("net.slice2.3.", "features.3."),
            ("net.slice3.6.", "features.6."),
            ("net.slice4.8.", "features.8."),
            ("net.slice5.10.", "features.10."),
        ] {
            if let Some(rest) = n.strip_prefix(lp) {
                return format!("{tv}{rest}");
            }
        }
        n.to_owned()
    };
    st.tensors()
        .into_iter()
        .filter(|(n, _)| !n.starts_with("scaling_layer"))
        .map(|(n, t)| Entry {
            name: rename(&n),
            shape: t.shape().to_vec(),
            data: t.data().to_vec(),
        })
        .collect()
}

fn unicode(out: &mut Vec<u8>, s: &str) {
    out.push(b'X');
    out.extend((s.len() as u32).to_le_bytes());
    out.extend(s.as_bytes());
}

fn int(out: &mut Vec<u8>, v: usize) {
    out.push(b'J');
    out.extend((v as i32).to_le_bytes());
}

fn int_tuple(out: &mut Vec<u8>, v: &[usize]) {
    out.push(b'(');
    for &d in v {
        int(out, d);
    }
    out.push(b't');
}

/// Pickle (protocol 2) of an OrderedDict name → _rebuild_tensor_v2(storage i, 0, shape, strides,
/// False, OrderedDict()), as torch.save writes a state_dict.
fn state_dict_pickle(entries: &[Entry]) -> Vec<u8> {
    let mut p = b"\x80\x02ccollections\nOrderedDict\n)R(".to_vec();
    for (i, e) in entries.iter().enumerate() {
        unicode(&mut p, &e.name);
        p.extend(b"ctorch._utils\n_rebuild_tensor_v2\n(");
        p.push(b'(');
        unicode(&mut p, "storage");
        p.extend(b"ctorch\nFloatStorage\n");
        unicode(&mut p, &i.to_string());
        unicode(&mut p, "cpu");
        int(&mut p, e.data.len() / 4);
        p.extend(b"NtQ");
        int(&mut p, 0);
        int_tuple(&mut p, &e.shape);
        let mut strides = vec![1; e.shape.len()];
        for d in (0..e.shape.len().saturating_sub(1)).rev() {
            strides[d] = strides[d + 1] * e.shape[d + 1];
        }
        int_tuple(&mut p, &strides);
        p.extend(b"\x89ccollections\nOrderedDict\n)RtR");
    }
    p.extend(b"u.");
    p
}

fn write_zip(path: &std::path::Path, entries: &[Entry]) {
    let mut z = zip::ZipWriter::new(std::fs::File::create(path).unwrap());
    let opts =
        zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    z.start_file("archive/data.pkl", opts).unwrap();
    z.write_all(&state_dict_pickle(entries)).unwrap();
    for (i, e) in entries.iter().enumerate() {
        z.start_file(format!("archive/data/{i}"), opts).unwrap();
        z.write_all(&e.data).unwrap();
    }
    z.start_file("archive/version", opts).unwrap();
    z.write_all(b"3\n").unwrap();
    z.finish().unwrap();
}

fn write_legacy(path: &std::path::Path, entries: &[Entry]) {
    let mut f: Vec<u8> = vec![
        0x80, 0x02, 0x8a, 0x0a, 0x6c, 0xfc, 0x9c, 0x46, 0xf9, 0x20, 0x6a, 0xa8, 0x50, 0x19, 0x2e,
    ];
    f.extend(b"\x80\x02M\xe9\x03.");
    f.extend(b"\x80\x02}(");
    unicode(&mut f, "little_endian");
    f.extend(b"\x88u.");
    f.extend(state_dict_pickle(entries));
    f.extend(b"\x80\x02](");
    for i in 0..entries.len() {
        unicode(&mut f, &i.to_string());
    }
    f.extend(b"e.");
    for e in entries {
        f.extend(((e.data.len() / 4) as i64).to_le_bytes());
        f.extend(&e.data);
    }
    std::fs::write(path, f).unwrap();
}

#[test]
fn loads_zip_and_legacy_checkpoints() {
    let dir = tempfile::tempdir().unwrap();
    let (heads, features): (Vec<Entry>, Vec<Entry>) = weights()
        .into_iter()
        .partition(|e| e.name.starts_with("lin"));
    assert_eq!((heads.len(), features.len()), (5, 10));
    let paths = |n: &str| dir.path().join(n);
    write_zip(&paths("alex_zip.pth"), &heads);
    write_legacy(&paths("alex_legacy.pth"), &heads);
    write_zip(&paths("alexnet_zip.pth"), &features);
    write_legacy(&paths("alexnet_legacy.pth"), &features);

    let reference = Lpips::load(&[common::LPIPS_WEIGHTS]).unwrap();
    let p = common::load("wide");
    let (a, b) = (p.render32(), p.target32());
    let expected = reference.distance(&a, &b, p.height, p.width).unwrap();
    assert!((expected - p.meta["lpips_alex_random_weights"]).abs() < 1e-5);
    for (h, f) in [
        ("alex_zip.pth", "alexnet_legacy.pth"),
        ("alex_legacy.pth", "alexnet_zip.pth"),
    ] {
        // The default scaling-layer constants equal the ones stored in the safetensors file.
        let net = Lpips::load(&[paths(h), paths(f)]).unwrap();
        let v = net.distance(&a, &b, p.height, p.width).unwrap();
        assert!((v - expected).abs() < 1e-6, "{h} + {f}: {v} vs {expected}");
    }
    // Missing the backbone: one clear error naming the tensor.
    let err = Lpips::load(&[paths("alex_zip.pth")])
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("features.0.weight") && err.contains("alex_zip.pth"),
        "{err}"
    );
    // Garbage file: an error naming it, no panic.
    std::fs::write(paths("junk.pth"), b"not a checkpoint at all").unwrap();
    let err = Lpips::load(&[paths("junk.pth")]).err().unwrap().to_string();
    assert!(err.contains("junk.pth"), "{err}");
}
