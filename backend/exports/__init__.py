"""Label export: jobs, archives and the glue that feeds worker.formats from the database."""
