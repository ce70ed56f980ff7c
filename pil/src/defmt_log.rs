//! The defmt log of an image run under QEMU (semihosting stdout), decoded with the table of the
//! ELF that produced it: the one decoder of the workspace (xtask and `shimmy-sim pil`).

/// Decodes a defmt byte stream with the table of the ELF that produced it: one line per
/// frame, prefixed with its level.
pub fn decode(elf: &[u8], stream: &[u8]) -> Result<Vec<String>, String> {
    let table = defmt_decoder::Table::parse(elf)
        .map_err(|e| format!("defmt table: {e}"))?
        .ok_or("the ELF has no defmt table")?;
    let mut decoder = table.new_stream_decoder();
    decoder.received(stream);
    let mut lines = Vec::new();
    loop {
        match decoder.decode() {
            Ok(frame) => {
                let level = frame
                    .level()
                    .map(|l| l.as_str().to_uppercase())
                    .unwrap_or_default();
                lines.push(format!("{level} {}", frame.display_message()));
            }
            Err(defmt_decoder::DecodeError::UnexpectedEof) => break,
            Err(defmt_decoder::DecodeError::Malformed) => {
                if table.encoding().can_recover() {
                    lines.push("(malformed defmt frame skipped)".into());
                } else {
                    return Err("malformed defmt frame".into());
                }
            }
        }
    }
    Ok(lines)
}
