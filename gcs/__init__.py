"""Ground-station library and the `returnlink gcs` command line."""
