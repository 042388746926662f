"""The built-in MTurk-compatible marketplace.

Requesters reach it with boto3's ``mturk`` client (``endpoint_url=<app>/mturk``): the Requester
API 2017-01-17 over JSON 1.1, signed with SigV4, validated against botocore's own service model.
Workers reach it through the service functions in ``workers`` (the worker portal) and the
``/mturk/externalSubmit`` form post that an ExternalQuestion page makes.
"""
