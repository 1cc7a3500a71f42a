//! Tessera's farm server (API, scheduler, persistence, tile assembly). Filled by the
//! farm-server issue; it depends on the tracer only to validate scenes and make previews.
