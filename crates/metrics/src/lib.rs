//! Image-quality metrics: what the stages optimize and what the report and `gsi compare`
//! measure ([`metrics`]). No other part of gsi is needed to use them.

pub mod metrics;
