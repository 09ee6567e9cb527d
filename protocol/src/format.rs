//! The blob's frame constants: magic, format versions, header and trailer lengths.

/// Four bytes that open every blob.
pub const MAGIC: [u8; 4] = *b"CBDM";
/// Version of the payload layout; bumped on any incompatible change.
/// Format 9 appends the provenance ([`Model::provenance`]: the import frame, the parent blob's
/// hash), an `Option` in postcard, after the format-8 drift; [`encode`]
/// writes it only for a model that has one.
/// Format 8 appends the configuration-dependent task field's kernel ([`Model::configuration_kernel`])
/// and the drift in measurement order ([`Model::drift`]), each an `Option` in postcard, after the
/// format-7 σ; [`encode`] writes it only for a model that has either.
/// Format 7 appends the noise σ the calibration assumed ([`Model::noise_sigma`]) after the format-6
/// payload; [`encode`] writes it only for a model that carries one.
/// Format 6 appends the DH chain's tool points ([`DhChain::tool_points`]) after the format-5
/// payload; [`encode`] writes it only for a model that names tool points (older models keep their bytes).
/// Format 5 appends the fields' expansions ([`FieldExpansion`]) after the format-4 payload;
/// format 4 adds the gravity moment effect ([`Effect::GravityMoment`]); formats 2 and 3 have
/// the same layout without it and load unchanged. [`encode`] writes format 4 when a model has no
/// expansion (byte-identical to the encoders before format 5), format 5 when it has one.
pub const FORMAT_VERSION: u16 = 9;
/// The format of a model with a configuration kernel or a drift and without a provenance.
pub const FORMAT_WITH_CONFIGURATION_KERNEL: u16 = 8;
/// The format of a model with a noise σ and without a configuration kernel.
pub const FORMAT_WITH_NOISE_SIGMA: u16 = 7;
/// The format of a model with tool points and without a noise σ.
pub const FORMAT_WITH_TOOL_POINTS: u16 = 6;
/// The format of a model with an expansion and without tool points.
pub const FORMAT_WITH_EXPANSION: u16 = 5;
/// The format of a model without an expansion.
pub const FORMAT_WITHOUT_EXPANSION: u16 = 4;
/// The oldest format this build reads (format 2 lacks the Hamiltonian momentum laws, formats 2
/// and 3 the gravity moment effect).
pub const OLDEST_FORMAT_VERSION: u16 = 2;
/// Bytes before the payload: magic, version, payload length.
pub const HEADER_LEN: usize = 10;
/// Bytes after the payload: the checksum.
pub const TRAILER_LEN: usize = 4;
